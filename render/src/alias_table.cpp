#include "phos/render/alias_table.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "phos/util/error.h"

namespace phos::render {
namespace {

struct VoseScratch {
  std::vector<double> scaled;
  std::vector<std::uint32_t> small, large;
};

// Vose over `weight[0, n)` (summing to `total`) and `padded - n` more
// columns of weight 0, into `columns[0, padded)`, aliases numbered from
// `first`: weights scaled so the mean is 1; each under-full column is
// topped up by an over-full one, its alias.
void BuildBlock(const double* weight, std::size_t n, std::size_t padded, double total, std::uint32_t first,
                AliasTable::Column* columns, VoseScratch& scratch) {
  std::vector<double>& scaled = scratch.scaled;
  std::vector<std::uint32_t>&small = scratch.small, &large = scratch.large;
  scaled.resize(padded);
  small.clear();
  large.clear();
  for (std::size_t e = 0; e < padded; ++e) {
    scaled[e] = e < n ? weight[e] / total * static_cast<double>(padded) : 0.0;
    (scaled[e] < 1.0 ? small : large).push_back(static_cast<std::uint32_t>(e));
    columns[e] = {1.0f, first + static_cast<std::uint32_t>(e)};
  }
  std::uint32_t heavy = large.empty() ? 0 : large.back();  // some column of weight
  while (!small.empty() && !large.empty()) {
    const std::uint32_t under = small.back(), over = large.back();
    small.pop_back();
    columns[under] = {static_cast<float>(scaled[under]), first + over};
    scaled[over] -= 1.0 - scaled[under];
    heavy = over;
    if (scaled[over] < 1.0) {
      large.pop_back();
      small.push_back(over);
    }
  }
  // What remains is full up to rounding: kept with probability 1, but for
  // a column of no weight (possible only by rounding), never kept.
  for (std::uint32_t e : small)
    if (!(scaled[e] > 0)) columns[e] = {0.0f, first + heavy};
}

}  // namespace

AliasTable::AliasTable(const double* weight, std::size_t n, Levels levels, int block_bits)
    : size_(n), block_bits_(block_bits) {
  PHOS_CHECK(block_bits >= 1 && block_bits <= kBlockBits && (levels == Levels::kBlocks || block_bits == kBlockBits));
  PHOS_CHECK(n > 0 && n < std::numeric_limits<std::uint32_t>::max() - kBlock);
  // A table of up to kOneBlock weights is one block, of as many columns; a
  // larger one has blocks of kBlock columns, the last block's columns past
  // the weights weighing 0 (so each is its alias), and a column is chosen
  // from random bits by a shift alone.
  blocked_ = n > kOneBlock || levels == Levels::kBlocks;
  const std::size_t block_size = blocked_ ? std::size_t{1} << block_bits : n;
  const std::size_t block_count = (n + block_size - 1) / block_size;
  columns_.resize(block_count * block_size);  // not zeroed: each is written below
  std::vector<double> block_weight(block_count);
  std::vector<char> valid(block_count);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, block_count, 1), [&](const tbb::blocked_range<std::size_t>& r) {
    VoseScratch scratch;
    for (std::size_t b = r.begin(); b < r.end(); ++b) {
      const std::size_t begin = b * block_size, size = std::min(block_size, n - begin);
      double sum = 0;
      bool ok = true;
      for (std::size_t i = begin; i < begin + size; ++i) {
        ok &= weight[i] >= 0 && std::isfinite(weight[i]);
        sum += weight[i];
      }
      block_weight[b] = sum;
      valid[b] = ok && std::isfinite(sum);
      // A block of no weight is never chosen: its columns only need to be valid.
      BuildBlock(weight + begin, size, block_size, sum > 0 ? sum : 1.0, static_cast<std::uint32_t>(begin),
                 columns_.data() + begin, scratch);
    }
  });
  double total = 0;  // the blocks' sums in order: the same on any number of threads
  for (std::size_t b = 0; b < block_count; ++b) {
    PHOS_CHECK(valid[b]);
    total += block_weight[b];
  }
  PHOS_CHECK(total > 0 && std::isfinite(total));
  blocks_ = BlockTable(block_weight.data(), block_count);
  block_sums_ = std::move(block_weight);
}

std::vector<AliasTable::Column> AliasTable::BlockTable(const double* weight, std::size_t count) {
  PHOS_CHECK(count > 0 && count < std::numeric_limits<std::uint32_t>::max());
  double total = 0;  // in order: the same on any number of threads
  for (std::size_t b = 0; b < count; ++b) {
    PHOS_CHECK(weight[b] >= 0 && std::isfinite(weight[b]));
    total += weight[b];
  }
  PHOS_CHECK(total > 0 && std::isfinite(total));
  std::vector<Column> items(count);
  VoseScratch scratch;
  BuildBlock(weight, count, count, total, 0, items.data(), scratch);
  return items;
}

std::vector<double> AliasTable::Probabilities(const std::vector<Column>& items) const {
  PHOS_CHECK(items.size() >= blocks_.size());
  const std::size_t extra = items.size() - blocks_.size();
  std::vector<double> p(size_ + extra, 0.0);
  PHOS_CHECK(extra == 0 || blocked_);
  const std::size_t block_size = blocked_ ? std::size_t{1} << block_bits_ : columns_.size();
  // The blocks' (and items') probabilities, then each block's columns' shares of its own.
  std::vector<double> block_p(items.size(), 0.0);
  for (std::size_t b = 0; b < items.size(); ++b) {
    const double share = 1.0 / static_cast<double>(items.size());
    block_p[b] += share * items[b].keep;
    block_p[items[b].alias] += share * (1.0 - static_cast<double>(items[b].keep));
  }
  for (std::size_t j = 0; j < extra; ++j) p[size_ + j] = block_p[blocks_.size() + j];
  for (std::size_t c = 0; c < columns_.size(); ++c) {
    const double share = block_p[c / block_size] / static_cast<double>(block_size);
    const double keep = std::clamp(static_cast<double>(columns_[c].keep), 0.0, 1.0);
    if (c < size_) p[c] += share * keep;
    else PHOS_CHECK(!(keep > 0 && keep < 1));  // padding: its own (never chosen by weight) or its alias
    if (keep < 1) p[columns_[c].alias] += share * (1.0 - keep);
  }
  return p;
}

}  // namespace phos::render
