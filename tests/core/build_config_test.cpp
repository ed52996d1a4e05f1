// Guards the build configuration itself: a Sanitize build that silently lost its sanitizer
// flags would pass every test while checking nothing.
#include <gtest/gtest.h>

namespace carousel {
namespace {

TEST(BuildConfigTest, SanitizeBuildIsInstrumented) {
#if defined(CAROUSEL_SANITIZE_BUILD)
#if defined(__SANITIZE_ADDRESS__)
  SUCCEED();
#else
  FAIL() << "Sanitize build compiled without -fsanitize=address";
#endif
#else
#if defined(__SANITIZE_ADDRESS__)
  FAIL() << "AddressSanitizer enabled outside the Sanitize build type";
#else
  SUCCEED();
#endif
#endif
}

#if defined(CAROUSEL_SANITIZE_BUILD)
// Only in the Sanitize build: ASan must abort the process on an out-of-bounds write.
TEST(BuildConfigTest, SanitizerCatchesAHeapOverflow) {
  EXPECT_DEATH(
      {
        volatile int* block = new int[4];
        block[4] = 1;
        delete[] block;
      },
      "heap-buffer-overflow|insufficient space");
}

// UndefinedBehaviorSanitizer must stop on signed overflow (recovery is off).
TEST(BuildConfigTest, SanitizerCatchesSignedOverflow) {
  EXPECT_DEATH(
      {
        volatile int big = 2147483647;
        volatile int sum = big + 1;
        (void)sum;
      },
      "signed integer overflow");
}
#endif

}  // namespace
}  // namespace carousel
