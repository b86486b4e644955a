// A discrete distribution sampled in O(1): the path tracer's choice of a
// glowing triangle in proportion to its power (transport_path.cpp), rebuilt
// every frame as the glow changes.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "phos/util/large_table.h"

namespace phos::render {

// An alias table (Walker 1977; Vose 1991's construction, as pbrt-v4's
// AliasTable) over n weights: index i is picked with probability w_i / W
// from one 64-bit random word, by one column read and one comparison. A
// binary search of a CDF over thousands of triangles was a tenth of the
// path tracer's time.
//
// A table of more than kOneBlock weights is two-level, so that it is built
// in parallel: blocks of kBlock columns, each an alias table of its own over
// its weights, under a small one over the blocks by their sums. Choosing a
// block by W_b / W and an index of it by w_i / W_b chooses the index by
// w_i / W, as one table over all would.
class AliasTable {
 public:
  struct Column {
    float keep;  // probability of keeping this column's index (or block) over its alias
    std::uint32_t alias;
  };
  // A table of up to kOneBlock weights (an 82k-triangle glowing mesh) is one
  // block, built in 0.3 ms on one core, and picks without the blocks' extra
  // step, which cost such a mesh 3% of the path/bare ratio with blocks of
  // 4096 (bench_render, BM_PathAgainstBareEmbreeGlowingBySize/6, three
  // alternated pairs). A larger one has blocks of kBlock: a power of 2, so
  // that a block's columns are chosen exactly uniformly from random bits;
  // small enough that a block's Vose works in a core's L1 and L2 caches
  // (with blocks of 2^17, a 1.3M-triangle mesh's tables took 2.2 ms to build
  // instead of 1.7).
  static constexpr std::size_t kOneBlock = std::size_t{1} << 17;
  static constexpr int kBlockBits = 12;
  static constexpr std::size_t kBlock = std::size_t{1} << kBlockBits;

  AliasTable() = default;
  // Over weight[0, n): each finite and >= 0, their sum finite and > 0 (a
  // program error otherwise). Every block's table is built in parallel, then
  // the one over the blocks; the same weights give the same table on any
  // number of threads. kBlocks: blocks of kBlock at any n (for reweighing,
  // below); kAuto: one block up to kOneBlock weights.
  // block_bits: with kBlocks, blocks of 2^block_bits columns (at most
  // kBlockBits, so that a keep's bits stay at least 20).
  enum class Levels { kAuto, kBlocks };
  AliasTable(const double* weight, std::size_t n, Levels levels = Levels::kAuto, int block_bits = kBlockBits);

  // Reweighing a table of blocks (the path tracer's large glowing meshes,
  // whose triangles are fixed but whose glow changes every frame): a table
  // over the blocks by other weights and, after them, over m items of the
  // caller's own (BlockTable over block_sums().size() + m weights, each
  // finite and >= 0, their sum W' finite and > 0), used with
  // Pick(random, items), picks index i of block b with probability
  // W'_b / W' * w_i / W_b, and the j-th item with W'_{blocks + j} / W'.
  // Built in O(blocks + m), so a frame pays for its blocks, not for their
  // columns.
  static std::vector<Column> BlockTable(const double* weight, std::size_t count);
  // Each block's sum of weights (W_b), in block order, and the blocks' size.
  const std::vector<double>& block_sums() const { return block_sums_; }
  int block_bits() const { return block_bits_; }

  std::size_t size() const { return size_; }
  bool empty() const { return size_ == 0; }
  // The columns, for a pick's prefetch (ColumnOf) and for tests:
  // block-major, kBlock to a block when there are blocks (the last block's
  // columns past the weights weigh 0: each keeps 1 or is never kept).
  const LargeTable<Column>& columns() const { return columns_; }
  const std::vector<Column>& blocks() const { return blocks_; }

  // One 64-bit random word. One block: its high half picks a column by
  // multiply-shift (Lemire), its low 24 bits decide between the column and
  // its alias. Blocks: its high half picks a block likewise, the product's
  // low 32 bits, uniform, deciding between the block and its alias, and its
  // low half picks a column of the block by its top kBlockBits and the
  // column or its alias by the other 20 (a keep rounded by at most 2^-20,
  // where one table's multiply-shift over 1.3M columns favoured some by
  // 3e-4). Masks, not branches: the choices are random, so a branch was
  // mispredicted at every other sample; whether there are blocks goes the
  // same way all frame.
  struct Choice {
    std::size_t column;
    float u;  // uniform in [0, 1): keep the column's index when below its keep
  };
  Choice ColumnOf(std::uint64_t random) const {
    if (blocks_.size() == 1)
      return {static_cast<std::size_t>(((random >> 32) * columns_.size()) >> 32), Unit24(static_cast<std::uint32_t>(random))};
    return ColumnOf(random, blocks_);
  }
  // With a table over the blocks and items of one's own (BlockTable): a
  // block's column, or columns().size() + j for the j-th item.
  Choice ColumnOf(std::uint64_t random, const std::vector<Column>& items) const {
    const std::uint64_t top = (random >> 32) * items.size();
    const std::uint32_t top_column = static_cast<std::uint32_t>(top >> 32);
    const std::uint32_t item = Select(top_column, items[top_column], Unit24(static_cast<std::uint32_t>(top) >> 8));
    const std::size_t blocks = block_sums_.size();
    if (item >= blocks) return {columns_.size() + (item - blocks), 0.0f};
    const std::uint32_t low = static_cast<std::uint32_t>(random);
    return {(std::size_t{item} << block_bits_) + (low >> (32 - block_bits_)), Unit24((low << block_bits_) >> 8)};
  }
  // The index the word picks.
  std::uint32_t Pick(std::uint64_t random) const { return Select(ColumnOf(random)); }
  // An index of this table, or columns().size() + j for the j-th item.
  std::uint32_t Pick(std::uint64_t random, const std::vector<Column>& items) const {
    const Choice choice = ColumnOf(random, items);
    return choice.column < columns_.size() ? Select(choice) : static_cast<std::uint32_t>(choice.column);
  }

  // Each index's probability as the table holds it (each column equally
  // likely, its keep as stored): what Pick draws but for the random bits'
  // rounding (at most 2^-20 of a keep, and one table's multiply-shift). For
  // tests; O(n).
  std::vector<double> Probabilities() const { return Probabilities(blocks_); }
  // With a table over the blocks and m items (BlockTable): size() + m
  // probabilities, the items' last.
  std::vector<double> Probabilities(const std::vector<Column>& items) const;

 private:
  std::uint32_t Select(const Choice& choice) const {
    return Select(static_cast<std::uint32_t>(choice.column), columns_[choice.column], choice.u);
  }
  static std::uint32_t Select(std::uint32_t column, const Column& c, float u) {
    const std::uint32_t keep = 0u - static_cast<std::uint32_t>(u < c.keep);
    return (column & keep) | (c.alias & ~keep);
  }
  static float Unit24(std::uint32_t bits) { return static_cast<float>(bits & 0xFFFFFFu) * (1.0f / 16777216.0f); }

  std::size_t size_ = 0;
  LargeTable<Column> columns_;  // [column]: aliases are indices
  std::vector<Column> blocks_;  // the table over the blocks (aliases are blocks)
  std::vector<double> block_sums_;
  int block_bits_ = kBlockBits;
  bool blocked_ = false;  // blocks of 2^block_bits_ columns (else one block of size_)
};

}  // namespace phos::render
