#include "carousel/core/parallel.h"

#include <algorithm>
#include <atomic>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

#include "carousel/core/error.h"

namespace carousel {

int ResolveThreadCount(int requested) {
  if (requested > 0) return requested;
  return static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
}

void ParallelFor(std::size_t count, std::size_t chunk, int threads,
                 const std::function<void(std::size_t begin, std::size_t end)>& body) {
  CAROUSEL_CHECK(chunk >= 1, "ParallelFor: chunk must be >= 1");
  if (count == 0) return;
  const std::size_t chunks = (count + chunk - 1) / chunk;
  const auto workers =
      static_cast<std::size_t>(std::min<std::size_t>(ResolveThreadCount(threads), chunks));
  if (workers <= 1) {
    for (std::size_t begin = 0; begin < count; begin += chunk)
      body(begin, std::min(count, begin + chunk));
    return;
  }
  std::atomic<std::size_t> next{0};
  std::mutex error_mutex;
  std::exception_ptr error;
  auto worker = [&] {
    try {
      for (std::size_t c = next++; c < chunks; c = next++) {
        const std::size_t begin = c * chunk;
        body(begin, std::min(count, begin + chunk));
      }
    } catch (...) {
      next = chunks;
      std::lock_guard<std::mutex> lock(error_mutex);
      if (!error) error = std::current_exception();
    }
  };
  {
    std::vector<std::jthread> pool;
    try {
      for (std::size_t i = 1; i < workers; ++i) pool.emplace_back(worker);
    } catch (...) {
      next = chunks;  // started workers stop; jthread joins them
      throw;
    }
    worker();
  }
  if (error) std::rethrow_exception(error);
}

}  // namespace carousel
