// ParallelFor: splits [0, count) into chunks handed to a small pool of worker threads.
//
// The calling thread works too. The first exception thrown by a chunk stops the hand-out of
// further chunks and is rethrown to the caller once every worker has finished (Cancelled from
// a Progress, out of memory, ...). Chunks are handed out in order, dynamically, so uneven work
// balances itself.
#pragma once

#include <cstddef>
#include <functional>

namespace carousel {

// Worker threads to use for `requested`, at least 1. 0 means the process's default: the count
// given to SetDefaultThreadCount, else $CAROUSEL_THREADS, else one per hardware thread. A batch
// running several sessions at once gives each of its processes a share of the cores this way.
int ResolveThreadCount(int requested);

// The count ResolveThreadCount(0) answers from now on (0: back to $CAROUSEL_THREADS or the
// hardware). \throw InvalidArgument when negative.
void SetDefaultThreadCount(int threads);

// Calls body(begin, end) for consecutive chunks of at most `chunk` items covering [0, count).
// \pre chunk >= 1. \throw whatever body throws (the first exception).
void ParallelFor(std::size_t count, std::size_t chunk, int threads,
                 const std::function<void(std::size_t begin, std::size_t end)>& body);

}  // namespace carousel
