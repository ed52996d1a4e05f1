#include "carousel/core/parallel.h"

#include <algorithm>
#include <atomic>
#include <cstdlib>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

#include <opencv2/core/utility.hpp>

#include "carousel/core/error.h"

namespace carousel {

namespace {

std::atomic<int> default_threads{0};

// $CAROUSEL_THREADS when it is a positive number (0 otherwise).
int EnvironmentThreadCount() {
  const char* text = std::getenv("CAROUSEL_THREADS");
  if (text == nullptr || *text == '\0') return 0;
  char* end = nullptr;
  const long value = std::strtol(text, &end, 10);
  if (*end != '\0' || value < 1 || value > 4096) return 0;
  return static_cast<int>(value);
}

}  // namespace

int ResolveThreadCount(int requested) {
  if (requested > 0) return requested;
  if (const int set = default_threads.load(); set > 0) return set;
  static const int environment = EnvironmentThreadCount();
  if (environment > 0) return environment;
  return static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
}

void SetDefaultThreadCount(int threads) {
  CAROUSEL_THROW_IF(threads < 0, InvalidArgument,
                    "thread count must be >= 0 (0 = one per core), got " << threads);
  default_threads = threads;
  // OpenCV's own pool too (a negative count restores its default).
  cv::setNumThreads(threads > 0 ? threads : -1);
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
