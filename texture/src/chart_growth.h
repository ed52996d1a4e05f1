// Internal: chart growth restricted to a region, for splitting a chart that will not flatten.
#pragma once

#include <vector>

#include "carousel/core/progress.h"
#include "carousel/texture/charts.h"
#include "face_graph.h"

namespace carousel::texture::internal {

// Splits the chart made of `faces` (a disk) into at least two disks grown from two far-apart
// seeds. Returns, per entry of `faces`, its part 0, 1, ... (more when the disk rule forces
// new seeds).
std::vector<int> SplitChart(const FaceGraph& graph, const std::vector<int>& faces,
                            const ChartOptions& options, Progress& progress);

}  // namespace carousel::texture::internal
