// The alias table (render/alias_table.h) against the distribution it is
// built from, on random weights and at the extremes:
//  - What the table holds (each index's probability from its columns) is
//    w_i / W: on weights drawn log-uniformly over 76 decades with zeros
//    among them, at sizes from 1 to past one block (a two-level table with
//    a padded last block). A weight of 0 is never picked.
//  - What Pick draws from random words follows what the table holds (chi
//    square over the indices, or over blocks and residues of a large table).
//  - One weight among zeros (even the least double) is picked every time;
//    equal weights just past one block are equal; weights of 1e300 and
//    1e-300 together; the same table on one thread and on two.
//  - A table of blocks reweighed (BlockTable, the path tracer's large
//    glowing meshes), with items of its own after the blocks, holds and
//    draws W'_b / W' * w_i / W_b and W'_j / W', at one block and many,
//    blocks of 2^12 and 2^8, blocks and items of weight 0 among them.
//  - Weights that are no distribution (negative, NaN, infinite, all zero)
//    are a program error, caught before any is picked.

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#include <tbb/task_arena.h>

#include "phos/render/alias_table.h"
#include "phos/util/random.h"

namespace phos::render {
namespace {

// Log-uniform over [1e-38, 1e38], a tenth of them 0.
std::vector<double> RandomWeights(std::size_t n, std::uint64_t seed) {
  SplitMix64 random(seed);
  std::vector<double> w(n);
  for (double& v : w) v = random.UniformDouble() < 0.1 ? 0.0 : std::pow(10.0, -38.0 + 76.0 * random.UniformDouble());
  w[n / 2] = 2.5;  // not all 0
  return w;
}

double Sum(const std::vector<double>& w) {
  double total = 0;
  for (double v : w) total += v;
  return total;
}

// The table holds w_i / W: in total variation to 1e-6, each index of at
// least a millionth of the mean weight to 1e-5 of itself, and no weight of 0
// with any probability.
void ExpectHolds(const std::vector<double>& w, const AliasTable& table) {
  const std::vector<double> p = table.Probabilities();
  ASSERT_EQ(p.size(), w.size());
  const double total = Sum(w), n = static_cast<double>(w.size());
  double variation = 0;
  for (std::size_t i = 0; i < w.size(); ++i) {
    const double expected = w[i] / total;
    variation += std::abs(p[i] - expected);
    if (w[i] == 0) {
      ASSERT_EQ(p[i], 0.0) << "index " << i << " of weight 0";
    }
    if (expected >= 1e-6 / n) {
      ASSERT_NEAR(p[i], expected, 1e-5 * expected) << "index " << i << " of " << w.size();
    }
  }
  EXPECT_LT(variation / 2, 1e-6) << w.size() << " weights";
}

TEST(AliasTable, HoldsRandomWeightsAtEverySize) {
  const std::size_t one_block = AliasTable::kOneBlock;
  for (std::size_t n : {std::size_t{1}, std::size_t{2}, std::size_t{7}, std::size_t{1000}, one_block, one_block + 1,
                        one_block + AliasTable::kBlock, std::size_t{300007}}) {
    const std::vector<double> w = RandomWeights(n, 17 + n);
    const AliasTable table(w.data(), n);
    EXPECT_EQ(table.size(), n);
    EXPECT_EQ(table.blocks().size() == 1, n <= one_block) << n;
    ExpectHolds(w, table);
  }
}

// Pearson's statistic of counts against probabilities (bins of expected
// count 0 must be empty).
double ChiSquare(const std::vector<double>& count, const std::vector<double>& p, double draws) {
  double chi2 = 0;
  for (std::size_t k = 0; k < count.size(); ++k) {
    if (p[k] == 0) {
      EXPECT_EQ(count[k], 0.0) << "bin " << k << " has no probability";
      continue;
    }
    const double expected = p[k] * draws, d = count[k] - expected;
    chi2 += d * d / expected;
  }
  return chi2;
}
// Above df + 6 sqrt(2 df): a chance below 1e-6 for a table that draws as it holds.
double ChiSquareBound(std::size_t bins) {
  const double df = static_cast<double>(bins) - 1;
  return df + 6 * std::sqrt(2 * df);
}

TEST(AliasTable, PicksDrawWhatTheTableHolds) {
  constexpr int kDraws = 1 << 22;
  {  // one block: every index its own bin (weights within 1e4 of each other)
    std::vector<double> w(61);
    SplitMix64 random(5);
    for (double& v : w) v = std::pow(10.0, 4.0 * random.UniformDouble());
    w[13] = 0;
    const AliasTable table(w.data(), w.size());
    std::vector<double> count(w.size(), 0.0);
    SplitMix64 words(99);
    for (int d = 0; d < kDraws; ++d) ++count[table.Pick(words.Next())];
    EXPECT_LT(ChiSquare(count, table.Probabilities(), kDraws), ChiSquareBound(w.size()));
  }
  {  // blocks: by block, and by index modulo 97 (which mixes every block's columns)
    const std::size_t n = AliasTable::kOneBlock + 3 * AliasTable::kBlock + 123;
    std::vector<double> w(n);
    SplitMix64 random(6);
    for (double& v : w) v = random.UniformDouble() < 0.2 ? 0.0 : std::pow(10.0, 3.0 * random.UniformDouble());
    const AliasTable table(w.data(), n);
    ASSERT_GT(table.blocks().size(), 1u);
    const std::vector<double> p = table.Probabilities();
    const std::size_t blocks = table.blocks().size();
    std::vector<double> by_block(blocks, 0.0), p_block(blocks, 0.0), by_residue(97, 0.0), p_residue(97, 0.0);
    for (std::size_t i = 0; i < n; ++i) {
      p_block[i / AliasTable::kBlock] += p[i];
      p_residue[i % 97] += p[i];
    }
    SplitMix64 words(7);
    for (int d = 0; d < kDraws; ++d) {
      const std::uint32_t i = table.Pick(words.Next());
      ASSERT_LT(i, n) << "a padding column was picked";
      ASSERT_GT(w[i], 0.0) << "index " << i << " of weight 0 was picked";
      ++by_block[i / AliasTable::kBlock];
      ++by_residue[i % 97];
    }
    EXPECT_LT(ChiSquare(by_block, p_block, kDraws), ChiSquareBound(blocks));
    EXPECT_LT(ChiSquare(by_residue, p_residue, kDraws), ChiSquareBound(97));
  }
}

// What a table of blocks reweighed, with items after the blocks, should
// hold: W'_b / W' * w_i / W_b for index i of block b, W'_{blocks + j} / W'
// for item j (at size() + j).
std::vector<double> Reweighed(const std::vector<double>& w, const AliasTable& table, const std::vector<double>& item_w) {
  std::vector<double> p(w.size(), 0.0);
  const double total = Sum(item_w);
  const std::size_t block = std::size_t{1} << table.block_bits(), blocks = table.block_sums().size();
  for (std::size_t i = 0; i < w.size(); ++i) {
    const std::size_t b = i / block;
    if (item_w[b] > 0) p[i] = item_w[b] / total * w[i] / table.block_sums()[b];
  }
  for (std::size_t j = blocks; j < item_w.size(); ++j) p.push_back(item_w[j] / total);
  return p;
}

TEST(AliasTable, BlocksReweighedHoldAndDrawTheirNewWeights) {
  struct Case {
    std::size_t n;
    int block_bits;
    std::size_t items;  // after the blocks
  };
  for (const Case& c : {Case{100, AliasTable::kBlockBits, 0}, Case{7 * AliasTable::kBlock + 9, AliasTable::kBlockBits, 0},
                        Case{3000, 8, 0}, Case{3000, 8, 50}, Case{300, 8, 1}}) {
    SCOPED_TRACE(std::to_string(c.n) + " weights, blocks of 2^" + std::to_string(c.block_bits) + ", " +
                 std::to_string(c.items) + " items");
    const std::size_t n = c.n, block = std::size_t{1} << c.block_bits;
    SplitMix64 random(n + c.items);
    std::vector<double> w(n);
    for (double& v : w) v = random.UniformDouble() < 0.1 ? 0.0 : std::pow(10.0, 3.0 * random.UniformDouble());
    const AliasTable table(w.data(), n, AliasTable::Levels::kBlocks, c.block_bits);
    const std::size_t blocks = (n + block - 1) / block;
    ASSERT_EQ(table.blocks().size(), blocks);
    ASSERT_EQ(table.block_sums().size(), blocks);
    ASSERT_EQ(table.columns().size(), blocks * block);
    // Unreweighed, it is the table of w.
    ExpectHolds(w, table);
    std::vector<double> item_w(blocks + c.items);
    for (double& v : item_w) v = std::pow(10.0, 6.0 * random.UniformDouble());
    if (blocks > 2) item_w[1] = 0;  // a block never chosen
    if (c.items > 2) item_w[blocks + 1] = 0;  // an item never chosen
    const std::vector<AliasTable::Column> items = AliasTable::BlockTable(item_w.data(), item_w.size());
    const std::vector<double> expected = Reweighed(w, table, item_w), p = table.Probabilities(items);
    ASSERT_EQ(p.size(), n + c.items);
    for (std::size_t i = 0; i < p.size(); ++i) {
      if (expected[i] == 0) ASSERT_EQ(p[i], 0.0) << "index " << i;
      else ASSERT_NEAR(p[i], expected[i], 1e-5 * expected[i]) << "index " << i;
    }
    // Draws: by block (an item its own bin), and by index modulo 97.
    constexpr int kDraws = 1 << 21;
    const std::size_t bins = blocks + c.items;
    auto bin_of = [&](std::size_t i) { return i < n ? i / block : blocks + (i - n); };
    std::vector<double> by_bin(bins, 0.0), p_bin(bins, 0.0), by_residue(97, 0.0), p_residue(97, 0.0);
    for (std::size_t i = 0; i < p.size(); ++i) {
      p_bin[bin_of(i)] += p[i];
      p_residue[i % 97] += p[i];
    }
    SplitMix64 words(n + 1);
    for (int d = 0; d < kDraws; ++d) {
      std::uint32_t i = table.Pick(words.Next(), items);
      if (i >= table.columns().size()) i = static_cast<std::uint32_t>(n + (i - table.columns().size()));  // item j
      else ASSERT_LT(i, n) << "a padding column was picked";
      ASSERT_GT(expected[i], 0.0) << "index " << i << " of no probability was picked";
      ++by_bin[bin_of(i)];
      ++by_residue[i % 97];
    }
    if (bins > 1) {
      EXPECT_LT(ChiSquare(by_bin, p_bin, kDraws), ChiSquareBound(bins));
    }
    EXPECT_LT(ChiSquare(by_residue, p_residue, kDraws), ChiSquareBound(97));
  }
}

TEST(AliasTable, OneWeightAmongZerosIsAlwaysPicked) {
  const std::size_t n = AliasTable::kOneBlock + 5000;
  for (double weight : {1.0, 1e-300, std::numeric_limits<double>::denorm_min(), 1e300}) {
    for (std::size_t at : {std::size_t{0}, std::size_t{77777}, n - 1}) {
      std::vector<double> w(n, 0.0);
      w[at] = weight;
      const AliasTable table(w.data(), n);
      SplitMix64 words(at);
      for (int d = 0; d < 100000; ++d) ASSERT_EQ(table.Pick(words.Next()), at) << "weight " << weight;
      ExpectHolds(w, table);
    }
  }
}

TEST(AliasTable, EqualWeightsJustPastOneBlockAreEquallyLikely) {
  const std::size_t n = AliasTable::kOneBlock + 1;  // the last block: one weight, 4095 padding columns
  const std::vector<double> w(n, 0.37);
  const AliasTable table(w.data(), n);
  const std::vector<double> p = table.Probabilities();
  for (std::size_t i = 0; i < n; ++i) ASSERT_NEAR(p[i], 1.0 / static_cast<double>(n), 1e-6 / static_cast<double>(n));
}

TEST(AliasTable, WeightsAtBothEndsOfTheDoubleRange) {
  std::vector<double> w(5000);
  for (std::size_t i = 0; i < w.size(); ++i) w[i] = i % 3 == 0 ? 1e300 : i % 3 == 1 ? 1e-300 : 0.0;
  const AliasTable table(w.data(), w.size());
  ExpectHolds(w, table);
  SplitMix64 words(3);
  for (int d = 0; d < 100000; ++d) ASSERT_EQ(table.Pick(words.Next()) % 3, 0u);  // 1e-300 is 1e-600 of the rest
}

TEST(AliasTable, TheSameOnOneThreadAndOnTwo) {
  const std::vector<double> w = RandomWeights(300007, 11);
  const AliasTable two(w.data(), w.size());
  AliasTable one;
  tbb::task_arena(1).execute([&] { one = AliasTable(w.data(), w.size()); });
  ASSERT_EQ(one.columns().size(), two.columns().size());
  for (std::size_t c = 0; c < one.columns().size(); ++c) {
    ASSERT_EQ(one.columns()[c].keep, two.columns()[c].keep) << c;
    ASSERT_EQ(one.columns()[c].alias, two.columns()[c].alias) << c;
  }
  ASSERT_EQ(one.blocks().size(), two.blocks().size());
  for (std::size_t b = 0; b < one.blocks().size(); ++b) {
    ASSERT_EQ(one.blocks()[b].keep, two.blocks()[b].keep) << b;
    ASSERT_EQ(one.blocks()[b].alias, two.blocks()[b].alias) << b;
  }
}

TEST(AliasTableDeathTest, WeightsThatAreNoDistributionAreAProgramError) {
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  const auto build = [](std::vector<double> w) { AliasTable table(w.data(), w.size()); };
  const char* failed = "internal error: .*alias_table.cpp:[0-9]+: check failed";
  EXPECT_DEATH(build({1.0, -0.5, 2.0}), failed);
  EXPECT_DEATH(build({1.0, std::nan(""), 2.0}), failed);
  EXPECT_DEATH(build({1.0, std::numeric_limits<double>::infinity()}), failed);
  EXPECT_DEATH(build({0.0, 0.0, 0.0}), failed);
  EXPECT_DEATH(build({1e308, 1e308}), failed);  // their sum is not finite
  EXPECT_DEATH(build({}), failed);
}

}  // namespace
}  // namespace phos::render
