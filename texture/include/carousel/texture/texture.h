// texture: the high-resolution texture atlas of shared/reference/texture-paper.md
// (contract; issues 5 and 6 build it).
//
// Atlas (paper sections 1-3): chart growth partitioning (Cost1/Cost2, seed upgrade), ABF++
// flattening with least-squares vertex reconstruction, minimum-area OBB packing with a gutter
// and equal texel density. Writes Mesh::chart_id and per-halfedge UVs.
// Texture (sections 4-5): front image per face (Mesh::front_view) with visibility and island
// cleanup, per-texel transfer through each view's CameraModel, missing-colour correction from
// masks, seam blending (Eq. 8), gain adjustment, gutter dilation; OBJ/MTL/PNG and GLB export;
// quality report. Takes std::vector<View>; never includes calib or recon.
#pragma once
