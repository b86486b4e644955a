#include "phos/util/large_table.h"

#include <gtest/gtest.h>

#include <cstdint>
#include <numeric>

#include "phos/util/random.h"

namespace phos {
namespace {

// Peek(k) is what the (k+1)-th Next() will return, and it draws nothing: the
// path tracer fetches the memory a future draw will index by it.
TEST(SplitMix64, PeekIsTheDrawThatFollowsWithoutDrawing) {
  for (std::uint64_t seed : {0ull, 1ull, 0x9E3779B97F4A7C15ull, ~0ull}) {
    SplitMix64 stream(seed);
    const std::uint64_t ahead0 = stream.Peek(), ahead1 = stream.Peek(1), ahead5 = stream.Peek(5);
    EXPECT_EQ(stream.Peek(), ahead0);  // peeking drew nothing
    std::uint64_t draws[6];
    for (std::uint64_t& d : draws) d = stream.Next();
    EXPECT_EQ(draws[0], ahead0);
    EXPECT_EQ(draws[1], ahead1);
    EXPECT_EQ(draws[5], ahead5);
  }
}

// A large table lies on 2 MiB boundaries (so the kernel can back it with huge
// pages); a small one keeps its type's alignment. Both hold what is written.
TEST(LargeTable, LargeStorageIsHugePageAlignedAndHoldsItsValues) {
  const std::size_t n = (std::size_t{5} << 20) / sizeof(std::uint32_t) + 3;  // 5 MiB and a bit
  LargeTable<std::uint32_t> large;
  large.resize(n);
  EXPECT_EQ(reinterpret_cast<std::uintptr_t>(large.data()) % LargeTableAllocator<std::uint32_t>::kHugePageBytes, 0u);
  std::iota(large.begin(), large.end(), 0u);
  EXPECT_EQ(large[n - 1], n - 1);
  large.push_back(7);  // growth reallocates through the same allocator and keeps the values
  EXPECT_EQ(large[n - 1], n - 1);
  EXPECT_EQ(large[n], 7u);

  struct alignas(64) Line {
    float values[16];
  };
  LargeTable<Line> small(3);
  EXPECT_EQ(reinterpret_cast<std::uintptr_t>(small.data()) % 64, 0u);
  LargeTable<float> filled;
  filled.assign(1000, 2.5f);  // assign fills as std::vector does
  for (float v : filled) ASSERT_EQ(v, 2.5f);
}

// A table rebuilt at the same size (the path tracer's, every frame) gets
// the block its predecessor freed, already faulted in: not a fresh one.
TEST(LargeTable, AFreedBlockIsReusedForATableOfItsSize) {
  const std::size_t n = (std::size_t{6} << 20) / sizeof(float);
  const float* first = nullptr;
  {
    LargeTable<float> table;
    table.assign(n, 1.0f);
    first = table.data();
  }
  LargeTable<float> again;
  again.resize(n);
  EXPECT_EQ(again.data(), first);
  again.assign(n, 3.0f);  // a reused block holds old contents until written
  EXPECT_EQ(again[n / 2], 3.0f);
}

}  // namespace
}  // namespace phos
