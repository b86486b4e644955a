// Path transport (renderer.h): the spectral path tracer, the reference. All
// bands travel together; next-event estimation for the lights and for the
// glowing triangles, combined with BSDF sampling by multiple importance
// sampling (power heuristic), so the glow of one surface lights the others
// (Fig. 8.15).
#include <algorithm>
#include <climits>
#include <cmath>
#include <memory>
#include <utility>
#include <vector>

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include "phos/render/alias_table.h"
#include "phos/render/bsdf.h"
#include "phos/util/error.h"
#include "phos/util/large_table.h"
#include "phos/util/math.h"
#include "phos/util/prefetch.h"
#include "phos/util/random.h"
#include "sampling.h"
#include "transport.h"

namespace phos::render {
namespace {

// Barycentric weights (b1, b2) of a uniform point on a triangle without a
// square root (Heitz 2019, "A Low-Distortion Map Between Triangle and
// Square", as pbrt-v4's SampleUniformTriangle). Its two cases (u1 < u2 or
// not) are one: each weight is its u less half the smaller u (u - u/2 = u/2
// exactly), so there is no branch, which went either way at random.
void SampleUniformTriangle(float u1, float u2, float& b1, float& b2) {
  const float half_min = std::min(u1, u2) / 2;
  b1 = u1 - half_min;
  b2 = u2 - half_min;
}

// The solver keeps Lp band-major ([band][texel], for its batch kernel), so
// one texel's bands lie a texel count apart: a cache miss per band for
// every path vertex that meets or samples a glow. The path tracer reads a
// texel-major copy made once per frame instead (in parallel), over the span
// of bands from the first emission band to the last (a band inside it that
// the phosphor does not emit holds 0), so a glow adds to consecutive bands,
// indexed directly. Through the list of emission bands, the two loops that
// add a glow held a tenth of TracePaths's samples (perf, bench_render
// --benchmark_filter=PathFrameDark1spp); indexed directly, the dark
// path/bare ratio is 0.988 of what it was (PathAgainstBareEmbree/40, eight
// alternated pairs).
struct GlowByTexel {
  int first_band = 0, band_count = 0;  // the span of emission bands
  LargeTable<float> Lp;                // [texel * band_count + i]: band first_band + i
};
// Everything a sample needs of its triangle in one cache line: sampling
// walked from the entry to the mesh's indices, its vertices and the atlas's
// per-triangle tables, a cache miss at each step.
struct alignas(64) EmitterEntry {
  Vec3f v0, e1, e2;  // the triangle: v0 + b1 e1 + b2 e2
  Vec3f normal;      // front
  float area_pdf;    // probability per m^2 of a point on it (by triangle; by blocks, see PickedAreaPdf)
  std::uint32_t triangle;
  std::uint32_t first_texel;  // auto atlas: its first texel
  std::int16_t slot;          // the object's texel slot
  std::uint16_t m;            // auto atlas: subdivisions (0: UV atlas, ask TexelOf)
  std::size_t Texel(const TexelAtlas& atlas, float b1, float b2) const {
    return m > 0 ? first_texel + static_cast<std::size_t>(SubTriangleIndex(m, b1, b2))
                 : atlas.TexelOf(slot, static_cast<int>(triangle), b1, b2);
  }
};

// A triangle's entry, written from the geometry and the atlas.
EmitterEntry MakeEmitterEntry(const SceneGeometry& geometry, const TexelAtlas::ObjectTexels& texels, int slot, int t) {
  EmitterEntry entry;
  const int object = texels.object;
  entry.v0 = geometry.Vertex(object, t, 0);
  entry.e1 = geometry.Vertex(object, t, 1) - entry.v0;
  entry.e2 = geometry.Vertex(object, t, 2) - entry.v0;
  entry.normal = geometry.FrontNormal(object, t);
  entry.area_pdf = 0;
  entry.triangle = static_cast<std::uint32_t>(t);
  entry.slot = static_cast<std::int16_t>(slot);
  entry.m = texels.uv() ? 0 : texels.m[t];
  entry.first_texel = texels.uv() ? 0 : texels.first[t];
  return entry;
}

// The glowing triangles of a large mesh, chosen by blocks: each object with
// more phosphorescent triangles than FrameOptions::emitter_blocks_above_triangles.
// Choosing each triangle by its power needs every triangle's power, entry
// and alias column anew every frame: with a 1.3M-triangle glowing mesh,
// about 7 ms of set-up in a frame whose rays bare Embree traces in 72
// (bench_render, BM_PathAgainstBareEmbreeGlowingBySize/8). Here the entries
// and, per block of kSize consecutive triangles of one object, a table
// choosing one by its area are built once and kept by the solver while
// nothing moves (CoupledSolver::DerivedTables); a frame only sums each
// block's power, with its glow's copy, and builds a table over the blocks
// and the other objects' glowing triangles. Block b is picked by W_b / W,
// then its triangle t by a_t / A_b: the area pdf of a point on t is
// W_b / (W A_b), the same all over the block. Unbiased, as the choice by
// triangle; its variance is that choice's where the glow is even over a
// block. Small objects stay chosen triangle by triangle: a Cornell box's
// wall is two triangles whose glow differs, and choosing them by area
// added 6% to the variance of a frame (BM_GlowChoiceByBlocks).
struct EmitterBlocks {
  static constexpr std::size_t kNone = ~std::size_t{0};
  static constexpr int kBits = 8;
  static constexpr std::size_t kSize = std::size_t{1} << kBits;  // triangles to a block
  std::size_t above_triangles = 0;               // the option it was built for
  std::vector<std::size_t> slot_first_column;    // per texel slot: a multiple of kSize; kNone: not by blocks
  std::vector<std::size_t> object_first_column;  // per object, likewise
  LargeTable<EmitterEntry> entries;              // per column; a padding column's is never picked
  AliasTable table;                              // over the columns by area, blocks of kSize
  bool By(int slot) const { return slot_first_column[slot] != kNone; }
};
// The texel slots chosen by blocks: those that emit, with more triangles than `above`.
std::vector<char> SlotsByBlocks(const SceneGeometry& geometry, const CoupledSolver& solver, std::size_t above) {
  const TexelAtlas& atlas = solver.atlas();
  std::vector<char> by(atlas.objects().size(), 0);
  for (std::size_t s = 0; s < by.size(); ++s)
    by[s] = !solver.emission_bands(static_cast<int>(s)).empty() &&
            static_cast<std::size_t>(geometry.triangle_count(atlas.objects()[s].object)) > above;
  return by;
}
std::shared_ptr<const EmitterBlocks> BuildEmitterBlocks(const SceneGeometry& geometry, const CoupledSolver& solver,
                                                        const std::vector<char>& by_blocks, std::size_t above) {
  auto blocks = std::make_shared<EmitterBlocks>();
  blocks->above_triangles = above;
  const TexelAtlas& atlas = solver.atlas();
  blocks->slot_first_column.assign(atlas.objects().size(), EmitterBlocks::kNone);
  blocks->object_first_column.assign(geometry.object_count(), EmitterBlocks::kNone);
  std::size_t columns = 0;
  std::vector<std::pair<std::size_t, int>> firsts;  // (first column, slot) of each slot by blocks, ascending
  for (std::size_t s = 0; s < atlas.objects().size(); ++s) {
    if (!by_blocks[s]) continue;
    const int object = atlas.objects()[s].object;
    blocks->slot_first_column[s] = blocks->object_first_column[object] = columns;
    firsts.emplace_back(columns, static_cast<int>(s));
    const std::size_t triangles = static_cast<std::size_t>(geometry.triangle_count(object));
    columns += (triangles + EmitterBlocks::kSize - 1) / EmitterBlocks::kSize * EmitterBlocks::kSize;
  }
  std::vector<double> area(columns, 0.0);
  blocks->entries.resize(columns);  // not zeroed: each is written below
  tbb::parallel_for(std::size_t{0}, columns / EmitterBlocks::kSize, [&](std::size_t b) {
    const std::size_t c0 = b * EmitterBlocks::kSize;
    const auto [first, slot] = *(std::upper_bound(firsts.begin(), firsts.end(), std::make_pair(c0, INT_MAX)) - 1);
    const TexelAtlas::ObjectTexels& texels = atlas.objects()[slot];
    const std::size_t triangles = static_cast<std::size_t>(geometry.triangle_count(texels.object));
    for (std::size_t c = c0; c < c0 + EmitterBlocks::kSize; ++c) {
      const std::size_t t = c - first;
      if (t < triangles) {
        blocks->entries[c] = MakeEmitterEntry(geometry, texels, slot, static_cast<int>(t));
        area[c] = geometry.Area(texels.object, static_cast<int>(t));
      } else {
        EmitterEntry& padding = blocks->entries[c];  // weighs 0: never picked
        padding.v0 = padding.e1 = padding.e2 = padding.normal = Vec3f::Zero();
        padding.area_pdf = 0;
        padding.triangle = padding.first_texel = 0;
        padding.slot = static_cast<std::int16_t>(slot);
        padding.m = 0;
      }
    }
  });
  blocks->table = AliasTable(area.data(), columns, AliasTable::Levels::kBlocks, EmitterBlocks::kBits);
  return blocks;
}
// The blocks, when some object is chosen by blocks; null otherwise.
std::shared_ptr<const EmitterBlocks> EmitterBlocksFor(const SceneGeometry& geometry, const CoupledSolver* solver,
                                                      const FrameOptions& options) {
  if (!solver) return nullptr;
  const std::size_t above = options.emitter_blocks_above_triangles;
  const std::vector<char> by_blocks = SlotsByBlocks(geometry, *solver, above);
  if (std::find(by_blocks.begin(), by_blocks.end(), 1) == by_blocks.end()) return nullptr;
  if (auto kept = std::static_pointer_cast<const EmitterBlocks>(solver->DerivedTables());
      kept && kept->above_triangles == above)
    return kept;
  std::shared_ptr<const EmitterBlocks> blocks = BuildEmitterBlocks(geometry, *solver, by_blocks, above);
  solver->KeepDerivedTables(blocks);
  return blocks;
}

// The frame's glow: the copy, and for the emitter table each triangle's
// power (the mean Lp of its texels, summed over bands, times its area) and
// the glowing triangles counted and their power summed in fixed chunks of a
// slot (kChunk), so that the total, the chunks' sums in order, rounds the
// same on any number of threads.
constexpr int kChunk = 16384;
struct GlowingChunk {
  int slot = 0, begin = 0, end = 0;  // triangles [begin, end) of the slot
  bool by_blocks = false;            // its slot is chosen by blocks (EmitterBlocks): it has no entries
  std::size_t glowing = 0;           // of them, those with power
  std::size_t first_entry = 0;       // the emitter entry of its first glowing triangle
  double power = 0;                  // theirs, summed in order
  // Counts and sums a triangle's power (in triangle order).
  void Add(double p) {
    if (p > 0) {
      ++glowing;
      power += p;
    }
  }
};
struct FrameGlow {
  std::vector<GlowByTexel> by_texel;      // per slot
  std::vector<LargeTable<double>> power;  // per slot, per triangle (empty: the slot emits no band, or by blocks)
  std::vector<double> block_power;        // by blocks (EmitterBlocks): per block of its table
  std::vector<GlowingChunk> chunks;       // every emitting slot's, in slot order
  std::size_t glowing = 0;                // glowing triangles chosen one by one (each an entry)
  std::size_t glowing_by_blocks = 0;      // the others
  double total = 0;                       // the power of all
};
// A triangle's power: the mean over its `count` texels of their Lp summed
// over bands (`Lp_sum`), times its area; 0 for a triangle without texels.
// One texel (most triangles of a mesh finer than its texels): the sum times
// the area, the same number without a division in the way of every triangle.
double TrianglePower(double Lp_sum, std::size_t count, double area_m2) {
  if (count == 1) return Lp_sum * area_m2;
  return count ? Lp_sum / static_cast<double>(count) * area_m2 : 0.0;
}
// A slot's glow as the solver keeps it, band by band: each emission band's
// Lp of every texel, at its place in the copy's span, and the texels'
// coverage (null: the paint covers every texel).
struct BandMajorGlow {
  std::vector<const float*> Lp;  // per emission band
  std::vector<int> place;        // its index in the span
  const float* coverage = nullptr;
  BandMajorGlow(const CoupledSolver& solver, int slot, const GlowByTexel& glow) {
    for (int b : solver.emission_bands(slot)) {
      Lp.push_back(solver.LpOfBand(slot, b));
      place.push_back(b - glow.first_band);
    }
    const std::vector<float>& c = solver.atlas().objects()[slot].coverage;
    coverage = c.empty() ? nullptr : c.data();
  }
  // Texels [k0, k1) into the copy, texel by texel (each texel's span
  // written once, in order: band by band, every pass over the run wrote
  // each of its cache lines again); returns their Lp summed over bands.
  double Copy(std::size_t k0, std::size_t k1, GlowByTexel& glow) const {
    const std::size_t span = static_cast<std::size_t>(glow.band_count), bands = Lp.size();
    float* out = glow.Lp.data() + k0 * span;
    double sum = 0;
    for (std::size_t k = k0; k < k1; ++k, out += span) {
      if (bands != span) std::fill(out, out + span, 0.0f);  // a band inside the span not emitted
      const float cover = coverage ? coverage[k] : 1.0f;  // a masked texel glows by the share its paint covers
      for (std::size_t e = 0; e < bands; ++e) {
        const float v = cover * Lp[e][k];
        out[place[e]] = v;
        sum += v;
      }
    }
    return sum;
  }
};
// An auto atlas's triangles own consecutive texels (m^2 from first, in
// triangle order), so the copy goes triangle by triangle and sums each
// one's power as it writes its texels: summed in a pass of its own, it
// read the whole copy back from memory. A UV atlas's texels fall on
// triangles in any order: copied by texel, then summed in texel order.
// By blocks (block_power not null: the slot's blocks), each triangle's
// power is added to its block's instead of kept: a chunk (kChunk, a
// multiple of EmitterBlocks::kSize) is whole blocks, so no two threads add
// to one.
void CopyGlowOfAutoAtlas(const SceneGeometry& geometry, const CoupledSolver& solver, GlowingChunk* chunks,
                         std::size_t chunk_count, GlowByTexel& glow, LargeTable<double>& power,
                         double* block_power) {
  const int slot = chunks[0].slot;
  const TexelAtlas::ObjectTexels& texels = solver.atlas().objects()[slot];
  const int triangles = geometry.triangle_count(texels.object);
  if (!block_power) power.resize(triangles);  // not zeroed: each is written below
  static_assert(kChunk % EmitterBlocks::kSize == 0);
  const BandMajorGlow from(solver, slot, glow);
  const std::uint32_t* first = texels.first.data();
  const std::uint16_t* m = texels.m.data();
  const float* area = geometry.Areas(texels.object);
  tbb::parallel_for(std::size_t{0}, chunk_count, [&](std::size_t c) {
    GlowingChunk& chunk = chunks[c];
    // The chunk's and each block's sums kept in locals (registers), each in
    // triangle order: added to in memory, every triangle waited on the last
    // one's store.
    GlowingChunk sums;
    for (int b0 = chunk.begin; b0 < chunk.end; b0 += static_cast<int>(EmitterBlocks::kSize)) {
      const int b1 = std::min(chunk.end, b0 + static_cast<int>(EmitterBlocks::kSize));
      double block_sum = 0;
      for (int t = b0; t < b1; ++t) {
        const std::size_t count = std::size_t{m[t]} * m[t];
        const double sum = from.Copy(first[t], first[t] + count, glow);
        const double p = TrianglePower(sum, count, area[t]);
        if (!block_power) power[t] = p;
        block_sum += p;
        sums.Add(p);
      }
      if (block_power) block_power[b0 >> EmitterBlocks::kBits] = block_sum;
    }
    chunk.glowing = sums.glowing;
    chunk.power = sums.power;
  });
}
void CopyGlowOfUvAtlas(const SceneGeometry& geometry, const CoupledSolver& solver, GlowingChunk* chunks,
                       std::size_t chunk_count, GlowByTexel& glow, LargeTable<double>& power) {
  const int slot = chunks[0].slot;
  const TexelAtlas& atlas = solver.atlas();
  const TexelAtlas::ObjectTexels& texels = atlas.objects()[slot];
  const BandMajorGlow from(solver, slot, glow);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, texels.count, 16384),
                    [&](const tbb::blocked_range<std::size_t>& r) { from.Copy(r.begin(), r.end(), glow); });
  // From the copy, as an auto atlas's: a masked texel's power is the share
  // its paint covers (the solver's Lp is the paint's own).
  const std::size_t span = static_cast<std::size_t>(glow.band_count);
  const int object = texels.object, triangles = geometry.triangle_count(object);
  power.assign(triangles, 0.0);
  std::vector<std::size_t> count(triangles, 0);
  atlas.ForEachTexel(slot, [&](std::size_t k, int t, float, float) {
    const float* Lp = glow.Lp.data() + k * span;
    for (std::size_t i = 0; i < span; ++i) power[t] += Lp[i];
    ++count[t];
  });
  for (int t = 0; t < triangles; ++t)
    power[t] = TrianglePower(power[t], count[t], geometry.Area(object, t));
  tbb::parallel_for(std::size_t{0}, chunk_count, [&](std::size_t c) {
    for (int t = chunks[c].begin; t < chunks[c].end; ++t) chunks[c].Add(power[t]);
  });
}
FrameGlow CopyGlow(const SceneGeometry& geometry, const CoupledSolver* solver, const EmitterBlocks* blocks) {
  FrameGlow glow;
  if (!solver) return glow;
  if (blocks) glow.block_power.assign(blocks->table.block_sums().size(), 0.0);
  const TexelAtlas& atlas = solver->atlas();
  glow.by_texel.resize(atlas.objects().size());
  glow.power.resize(atlas.objects().size());
  for (std::size_t s = 0; s < atlas.objects().size(); ++s) {
    const int slot = static_cast<int>(s), triangles = geometry.triangle_count(atlas.objects()[s].object);
    const std::vector<int>& bands = solver->emission_bands(slot);
    if (bands.empty() || triangles == 0) continue;  // it glows nowhere: no copy, no chunks, no power
    GlowByTexel& by_texel = glow.by_texel[s];
    by_texel.first_band = bands.front();
    by_texel.band_count = bands.back() - bands.front() + 1;
    by_texel.Lp.resize(atlas.objects()[s].count * static_cast<std::size_t>(by_texel.band_count));  // each written
    const bool by_blocks = blocks && blocks->By(slot);
    const std::size_t first_chunk = glow.chunks.size();
    for (int begin = 0; begin < triangles; begin += kChunk)
      glow.chunks.push_back({slot, begin, std::min(triangles, begin + kChunk), by_blocks});
    GlowingChunk* chunks = glow.chunks.data() + first_chunk;
    const std::size_t chunk_count = glow.chunks.size() - first_chunk;
    double* block_power =
        by_blocks ? glow.block_power.data() + (blocks->slot_first_column[s] >> EmitterBlocks::kBits) : nullptr;
    if (atlas.objects()[s].uv()) {
      CopyGlowOfUvAtlas(geometry, *solver, chunks, chunk_count, by_texel, glow.power[s]);
      if (block_power) {
        for (int t = 0; t < triangles; ++t) block_power[t >> EmitterBlocks::kBits] += glow.power[s][t];
        glow.power[s] = {};
      }
    } else {
      CopyGlowOfAutoAtlas(geometry, *solver, chunks, chunk_count, by_texel, glow.power[s], block_power);
    }
  }
  for (GlowingChunk& chunk : glow.chunks) {
    if (chunk.by_blocks) {
      glow.glowing_by_blocks += chunk.glowing;
    } else {
      chunk.first_entry = glow.glowing;
      glow.glowing += chunk.glowing;
    }
    glow.total += chunk.power;
  }
  return glow;
}

// The glowing triangles of this moment, for next-event estimation: chosen in
// proportion to their emitted power (texel Lp summed over bands, times area)
// by an alias table (alias_table.h), one by one or, in a large mesh, by
// blocks (EmitterBlocks).
struct EmitterDistribution {
  using Entry = EmitterEntry;
  // Large tables (large_table.h): a 1.3M-triangle glowing mesh has 83 MB of
  // entries, and zeroing that on one thread before filling it on two was
  // most of a frame's set-up.
  LargeTable<Entry> entries;           // the triangles chosen one by one that glow
  AliasTable table;                    // over the entries, by power (without blocks)
  std::vector<LargeTable<float>> pdf;  // per object, per triangle: probability of choosing it, per m^2 of it
  std::vector<std::uint8_t> two_sided;  // per texel slot: the object glows from both faces
  // With blocks: the kept entries and their table by area; this frame's
  // table over the blocks and then the entries, by power; each block's area
  // pdf, W_b / (W A_b). A pick's index below first_entry is a column of the
  // blocks' table; from first_entry on, entry index - first_entry.
  std::shared_ptr<const EmitterBlocks> blocks;
  std::vector<AliasTable::Column> items;
  std::vector<float> block_pdf;
  std::uint32_t first_entry = 0;

  bool empty() const { return blocks ? items.empty() : entries.empty(); }
  // The table outgrows a core's cache: a pick's column is then a cache miss,
  // worth fetching as soon as its random word is known.
  bool outgrows_cache() const {
    const std::size_t n = entries.size() + first_entry;
    return n * (sizeof(Entry) + sizeof(AliasTable::Column)) > kCoreCacheBytes;
  }

  // Built for every frame, as the glow changes, from each triangle's power
  // (summed with the frame's glow copy) in stages, each in parallel but for
  // sums over chunks and blocks: the glowing triangles counted and their
  // power summed by chunk, their entries, and the alias table. On one
  // thread it held a 1.3M-triangle glowing sphere's frame for longer than
  // bare Embree took to trace it (bench_render,
  // BM_PathAgainstBareEmbreeGlowingBySize/8). Of the blocks, only a table
  // over them is built.
  EmitterDistribution(const SceneGeometry& geometry, const CoupledSolver* solver, const FrameGlow& glow,
                      std::shared_ptr<const EmitterBlocks> by_blocks)
      : blocks(std::move(by_blocks)) {
    pdf.resize(geometry.object_count());
    if (!solver) return;
    const TexelAtlas& atlas = solver->atlas();
    PHOS_CHECK(atlas.objects().size() <= 32767);
    for (const TexelAtlas::ObjectTexels& texels : atlas.objects())
      two_sided.push_back(geometry.scene().objects[texels.object].two_sided);
    if (blocks) first_entry = static_cast<std::uint32_t>(blocks->entries.size());
    if (glow.glowing + glow.glowing_by_blocks == 0) return;
    const LargeTable<double> entry_power = WriteEntries(geometry, atlas, glow);
    if (!blocks) {
      table = AliasTable(entry_power.data(), entry_power.size());
      return;
    }
    // One table over the blocks, then the entries.
    std::vector<double> weight(glow.block_power);
    weight.insert(weight.end(), entry_power.begin(), entry_power.end());
    items = AliasTable::BlockTable(weight.data(), weight.size());
    const std::vector<double>& area = blocks->table.block_sums();
    block_pdf.resize(glow.block_power.size());
    for (std::size_t b = 0; b < block_pdf.size(); ++b)
      block_pdf[b] = area[b] > 0 ? static_cast<float>(glow.block_power[b] / glow.total / area[b]) : 0.0f;
  }
  // The glowing triangles' entries (of the objects chosen one by one), chunk
  // by chunk in parallel, and every triangle's area pdf (0 where it does not
  // glow) in the objects that glow; returns the entries' power.
  LargeTable<double> WriteEntries(const SceneGeometry& geometry, const TexelAtlas& atlas, const FrameGlow& glow) {
    const std::vector<LargeTable<double>>& power = glow.power;
    std::vector<char> slot_glows(atlas.objects().size(), 0);
    for (const GlowingChunk& chunk : glow.chunks) slot_glows[chunk.slot] |= !chunk.by_blocks && chunk.glowing > 0;
    for (std::size_t s = 0; s < slot_glows.size(); ++s)
      if (slot_glows[s]) pdf[atlas.objects()[s].object].resize(power[s].size());  // not zeroed: each is written below
    entries.resize(glow.glowing);  // not zeroed: each is written below
    LargeTable<double> entry_power;
    entry_power.resize(glow.glowing);
    tbb::parallel_for(std::size_t{0}, glow.chunks.size(), [&](std::size_t c) {
      const GlowingChunk& chunk = glow.chunks[c];
      if (!slot_glows[chunk.slot]) return;  // its object has no pdf table
      const TexelAtlas::ObjectTexels& texels = atlas.objects()[chunk.slot];
      const int object = texels.object;
      const LargeTable<double>& p = power[chunk.slot];
      LargeTable<float>& object_pdf = pdf[object];
      std::size_t e = chunk.first_entry;
      for (int t = chunk.begin; t < chunk.end; ++t) {
        if (!(p[t] > 0)) {
          object_pdf[t] = 0;
          continue;
        }
        Entry& entry = entries[e];
        entry = MakeEmitterEntry(geometry, texels, chunk.slot, t);
        entry.area_pdf = static_cast<float>(p[t] / glow.total / geometry.Area(object, t));
        object_pdf[t] = entry.area_pdf;
        entry_power[e++] = p[t];
      }
    });
    return entry_power;
  }
  // Probability per unit area of sampling a point of (object, triangle).
  float AreaPdf(int object, int triangle) const {
    if (blocks && blocks->object_first_column[object] != EmitterBlocks::kNone) {
      if (block_pdf.empty()) return 0.0f;
      return block_pdf[(blocks->object_first_column[object] + static_cast<std::size_t>(triangle)) >> EmitterBlocks::kBits];
    }
    const auto& p = pdf[object];
    return p.empty() ? 0.0f : p[triangle];
  }
  // A pick: the index of its entry.
  std::uint32_t Pick(std::uint64_t random) const {
    return blocks ? blocks->table.Pick(random, items) : table.Pick(random);
  }
  const Entry& entry(std::uint32_t picked) const {
    return picked < first_entry ? blocks->entries[picked] : entries[picked - first_entry];
  }
  // The area pdf of a point on the picked triangle.
  float PickedAreaPdf(std::uint32_t picked, const Entry& entry) const {
    return picked < first_entry ? block_pdf[picked >> EmitterBlocks::kBits] : entry.area_pdf;
  }
  // What the word's pick reads first (for its prefetch): its alias column,
  // or with blocks an entry chosen one by one.
  const void* FirstRead(std::uint64_t random) const {
    if (!blocks) return &table.columns()[table.ColumnOf(random).column];
    const std::size_t column = blocks->table.ColumnOf(random, items).column;
    return column < first_entry ? static_cast<const void*>(&blocks->table.columns()[column])
                                : static_cast<const void*>(&entries[column - first_entry]);
  }
};

class PathTransport final : public FrameTransport {
 public:
  PathTransport(const Shading& shading, const CameraRays& camera)
      : shading_(shading),
        camera_(camera),
        geometry_(shading.geometry()),
        scene_(shading.scene()),
        solver_(shading.solver()),
        media_(shading.media()),
        options_(shading.options()),
        nb_(shading.band_count()),
        blocks_(EmitterBlocksFor(geometry_, solver_, options_)),
        glow_(CopyGlow(geometry_, solver_, blocks_.get())),
        emitters_(geometry_, solver_, glow_, blocks_) {
    glow_.power = {};  // the emitter table's alone
    prefetch_emitters_ = emitters_.outgrows_cache();
  }

  // A row's pixels, spp samples each, traced a wavefront at a time.
  void RenderRow(int y, Image& image, std::uint64_t& rays) override {
    const int nb = nb_, width = image.width, spp = options_.spp;
    // A row's pixels trace their s-th samples together (TracePaths),
    // in the thread's wavefront.
    PathRow& row = rows_.local();
    std::vector<SplitMix64>& streams = row.streams;
    streams.clear();
    for (int x = 0; x < width; ++x) streams.push_back(PixelStream(options_, width, x, y));
    std::vector<Bands>& sums = row.sums;
    sums.assign(width, Bands::Zero(nb));
    // Pixels of a row in groups of 256: enough rays per stream call for
    // Embree to fill its packets (64 measured slower), few enough lanes for
    // the L2 cache (a whole row of 512 measured slower).
    constexpr int kLanes = 256;
    std::vector<PathLane>& lanes = row.wave.lanes;
    for (int x0 = 0; x0 < width; x0 += kLanes) {
      const int count = std::min(kLanes, width - x0);
      lanes.resize(count);
      for (int s = 0; s < spp; ++s) {
        for (int k = 0; k < count; ++k) {
          // One centred sample when there is one; jittered otherwise.
          const int x = x0 + k;
          SplitMix64& random = streams[x];
          const float jx = spp == 1 ? 0.5f : random.UniformFloat(), jy = spp == 1 ? 0.5f : random.UniformFloat();
          const Vec3f through = camera_.Through(static_cast<float>(x) + jx, static_cast<float>(y) + jy);
          lanes[k].Start(camera_.origin(), through.normalized(), CameraDifferential(shading_, camera_, through), random,
                         nb);
        }
        TracePaths(row.wave, rays);
        for (int k = 0; k < count; ++k) sums[x0 + k] += lanes[k].L;
      }
    }
    for (int x = 0; x < width; ++x) {
      sums[x] /= static_cast<float>(spp);
      std::copy(sums[x].data(), sums[x].data() + nb, image.at(x, y));
    }
  }

 private:
  // The texel-major glow of a hit on a phosphor's glowing side (path
  // transport): its emission bands and their Lp, prefetched; empty elsewhere.
  struct GlowTexel {
    int first_band = 0, band_count = 0;  // Lp[i] is band first_band + i's
    const float* Lp = nullptr;
    explicit operator bool() const { return Lp != nullptr; }
  };
  GlowTexel GlowAt(const Hit& hit) const {
    if (glow_.by_texel.empty() || !shading_.ShowsGlow(hit)) return {};
    const int slot = solver_->atlas().SlotOf(hit.object);
    if (slot < 0) return {};
    return GlowAt(slot, solver_->atlas().TexelOf(slot, hit.triangle, hit.b1, hit.b2));
  }
  GlowTexel GlowAt(int slot, std::size_t texel) const {
    const GlowByTexel& glow = glow_.by_texel[slot];
    if (glow.band_count == 0 || texel == TexelAtlas::kNoTexel) return {};
    const float* Lp = &glow.Lp[texel * static_cast<std::size_t>(glow.band_count)];
    Prefetch(Lp);
    return {glow.first_band, glow.band_count, Lp};
  }


  // A path of the path tracer, one per pixel sample in flight.
  struct PathLane {
    Vec3f origin, direction;
    RayDifferential differential;  // the camera ray's; bounces have none
    Bands L, beta;
    const Bands* albedo = nullptr;  // at this bounce's hit: the object's, or texture_albedo
    Bands texture_albedo;
    float bsdf_pdf = 0;  // solid-angle pdf of the direction that led here (0: camera ray)
    SplitMix64* random = nullptr;
    // This bounce (its hit is in the wavefront's hits): the shading normal,
    // the next ray's origin and the shadow ray to a point on a glowing
    // triangle (if glow_there).
    Vec3f n_s, origin_s, wi;
    float emitter_distance = 0, emitter_scale = 0;
    const Gloss* gloss = nullptr;  // a glossy hit's (the object's, or texture_gloss); null: Lambertian
    Gloss texture_gloss;
    Bands glow_f_cos;              // glossy: f cos toward the glowing point (emitter_scale then w / p_light)
    GlowTexel glow_there;
    GlowTexel glow_here;
    bool scatters = false;
    const EmitterDistribution::Entry* emitter = nullptr;  // the glowing triangle to sample
    std::uint32_t emitter_index = 0;                        // its pick
    void Start(const Vec3f& camera, const Vec3f& d, const RayDifferential& footprint, SplitMix64& stream, int nb) {
      origin = camera;
      direction = d;
      differential = footprint;
      L = Bands::Zero(nb);
      beta = Bands::Ones(nb);
      bsdf_pdf = 0;
      random = &stream;
    }
  };

  // A lane's shadow ray toward one of the lights (next-event estimation).
  struct LightShadowRay {
    int lane, light;
    const Hit* hit;  // the lane's hit this bounce
    LightRay ray;
  };
  // A thread's lanes and the lists of one bounce, kept from row to row: a
  // lane is 1.4 KB (four Bands of kMaxBands), and allocating and zeroing 256
  // of them for every row was 2.5% of a path-traced frame (perf, bench_render
  // --benchmark_filter=PathFrameDark1spp).
  struct Wavefront {
    std::vector<PathLane> lanes;
    std::vector<int> live, scattering, shadowed;
    std::vector<LightShadowRay> light_rays;
    // Written as each lane's ray is made, not in a pass over the lanes after:
    // the next closest-hit rays, and the shadow rays (to glowing points, then
    // to the lights).
    std::vector<SceneGeometry::RayQuery> queries, shadow_queries;
    std::vector<Hit> hits;
    std::vector<char> blocked;
  };

  // Traces every lane's path to its end, all lanes a bounce at a time (a
  // wavefront, as in Laine, Karras and Aila 2013, "Megakernels Considered
  // Harmful"): the closest hits of every live path, then their shading, then
  // their shadow rays, then their next directions. Traced one path at a time,
  // Embree's traversal and the shading evicted each other from the caches
  // and branch predictors at every ray: the path tracer took 1.8 to 2x the
  // time of bare Embree calls on its own rays (bench_render,
  // BM_PathAgainstBareEmbree). Each lane draws from its own stream in the
  // order a lone path would, so the result is the same as path by path.
  void TracePaths(Wavefront& wave, std::uint64_t& rays) const {
    std::vector<PathLane>& lanes = wave.lanes;
    std::vector<int>& live = wave.live;
    std::vector<int>& scattering = wave.scattering;
    std::vector<int>& shadowed = wave.shadowed;
    std::vector<LightShadowRay>& light_rays = wave.light_rays;
    std::vector<SceneGeometry::RayQuery>& queries = wave.queries;
    std::vector<SceneGeometry::RayQuery>& shadow_queries = wave.shadow_queries;
    std::vector<Hit>& hits = wave.hits;
    std::vector<char>& blocked = wave.blocked;
    live.resize(lanes.size());
    queries.clear();
    for (std::size_t i = 0; i < lanes.size(); ++i) {
      live[i] = static_cast<int>(i);
      queries.push_back({lanes[i].origin, lanes[i].direction});
    }
    for (int depth = 0; depth < options_.max_depth && !live.empty(); ++depth) {
      hits.resize(queries.size());
      geometry_.IntersectMany(queries.data(), queries.size(), hits.data(), /*coherent=*/depth == 0);
      rays += live.size();
      if (prefetch_emitters_) PrefetchEmitterPicks(lanes, live, depth);
      scattering.clear();
      shadowed.clear();
      light_rays.clear();
      shadow_queries.clear();
      for (std::size_t k = 0; k < live.size(); ++k) {
        const int i = live[k];
        PathLane& lane = lanes[i];
        if (!BeginVertex(lane, hits[k], depth)) continue;
        if (!ShadeVertex(lane, hits[k], i, depth, light_rays)) continue;
        scattering.push_back(i);
        if (lane.glow_there) {
          shadowed.push_back(i);
          shadow_queries.push_back(
              {lane.origin_s, lane.wi, lane.emitter_distance * (1 - 1e-4f) - 2 * geometry_.ray_epsilon()});
        }
      }
      // The shadow rays: to the glowing points, then to the lights.
      for (const LightShadowRay& shadow : light_rays)
        shadow_queries.push_back({shadow.ray.origin, shadow.ray.direction, shadow.ray.t_far});
      blocked.resize(shadow_queries.size());
      geometry_.OccludedMany(shadow_queries.data(), shadow_queries.size(), reinterpret_cast<bool*>(blocked.data()));
      rays += shadow_queries.size();
      // The glowing points, where nothing lies between.
      for (std::size_t k = 0; k < shadowed.size(); ++k) {
        if (blocked[k]) continue;
        PathLane& lane = lanes[shadowed[k]];
        const Bands& albedo = lane.gloss ? lane.glow_f_cos : *lane.albedo;  // glossy: f cos, else albedo (pi folded in)
        const GlowTexel& glow = lane.glow_there;
        for (int c = 0; c < glow.band_count; ++c) {
          const int b = glow.first_band + c;
          lane.L[b] += lane.beta[b] * albedo[b] * glow.Lp[c] * lane.emitter_scale;
        }
      }
      // The lights, where nothing (and no medium) lies between.
      for (std::size_t k = 0; k < light_rays.size(); ++k) {
        if (blocked[shadowed.size() + k]) continue;
        const LightShadowRay& shadow = light_rays[k];
        PathLane& lane = lanes[shadow.lane];
        const Shading::LitLight& light = shading_.lights()[shadow.light];
        float unit = shadow.ray.unit;
        if (media_) unit *= shading_.Transmittance(light.pose, shadow.hit->position);
        if (lane.gloss) {
          Bands f(nb_);
          GlossyBsdf(*lane.gloss, lane.albedo->data(), nb_).Eval(lane.n_s, -lane.direction, shadow.ray.direction, f.data());
          lane.L += lane.beta * f * light.E * unit;
        } else {
          lane.L += lane.beta * *lane.albedo * light.E * (unit * kInvPiF);
        }
      }
      live.clear();
      queries.clear();
      for (int i : scattering)
        if (ContinuePath(lanes[i], depth)) {
          live.push_back(i);
          queries.push_back({lanes[i].origin, lanes[i].direction});
        }
    }
  }

  // The alias column each lane's BeginVertex will read, asked for as soon
  // as the bounce's hits are in, before any lane is shaded. With a glowing
  // 1.3M-triangle sphere the column, read cold, was 70% of BeginVertex's
  // time (perf), and the path/bare ratio is 0.88 of what it was (five
  // alternated pairs, bench_render
  // --benchmark_filter=PathAgainstBareEmbreeGlowingBySize/8). The word that
  // picks a lane's emitter is its next draw (after the camera ray's media
  // draw), so it is known here without drawing it: results are unchanged,
  // and a vertex that picks nothing wasted one fetch. Tried and not kept:
  // asking as each ray is queued, a stream call earlier (the fetches did not
  // survive Embree's traversal: 0.95 without them), and a second pass
  // fetching the picked entries, the hit's atlas entry, its glow and its
  // area pdf (1.10 with it, six pairs: the prefetches themselves stalled).
  // Only when the table outgrows a core's cache (prefetch_emitters_).
  void PrefetchEmitterPicks(const std::vector<PathLane>& lanes, const std::vector<int>& live, int depth) const {
    const int skip = depth == 0 && media_ ? 1 : 0;
    for (int i : live) Prefetch(emitters_.FirstRead(lanes[i].random->Peek(skip)));
  }

  // A lane's vertex is BeginVertex then ShadeVertex, one lane after another.
  // They were once two passes over all the live lanes, so that the memory
  // BeginVertex prefetches (the glow here, the glowing triangle to sample)
  // would arrive while the other lanes began; one pass measured 2.5% faster
  // (bench_render, BM_PathAgainstBareEmbree/40, six alternated pairs): each
  // pass reloaded every lane.
  //
  // The first half of a vertex: the media of a camera ray, the sky on a
  // miss, the emission seen (area lights, emissive objects), and the
  // addresses of the glow here and of the glowing triangle to sample,
  // prefetched. False: the path ends at a miss.
  bool BeginVertex(PathLane& lane, const Hit& hit, int depth) const {
    SplitMix64& random = *lane.random;
    if (depth == 0 && media_) {
      // The camera ray's media (single scattering; later bounces pass
      // through them unattenuated, see volume.h).
      Bands Lm = Bands::Zero(nb_);
      lane.beta *= shading_.Media(lane.origin, lane.direction, hit, random.UniformFloat(), Lm);
      lane.L += Lm;
    }
    // The area lights this ray crosses: seen by the camera, or found by a
    // bounce and weighted against their next-event estimation (power
    // heuristic, p_light = d^2 / (cos_light A)).
    if (!shading_.area_lights().empty())
      shading_.AddAreaLightsSeen(lane.origin, lane.direction, hit ? hit.distance : 1e30f, lane.beta, lane.L,
                        [&](const LightPose& pose, const Vec3f& direction, float t) {
                          if (depth == 0) return 1.0f;
                          const float p_light = t * t / (-pose.normal.dot(direction) * pose.area_m2);
                          return PowerHeuristic(lane.bsdf_pdf, p_light);
                        });
    // An emissive object's front, likewise.
    if (const Bands* Le = hit ? shading_.EmitterAt(hit) : nullptr) {
      float weight = 1;
      if (depth > 0) {
        const float cos_light = -hit.normal.dot(lane.direction);
        const float p_light = hit.distance * hit.distance / (cos_light * geometry_.EmitterArea(hit.object));
        weight = PowerHeuristic(lane.bsdf_pdf, p_light);
      }
      lane.L += lane.beta * *Le * weight;
    }
    if (!hit) {
      // The sky, found by the camera ray or a bounce (cosine sampling; no
      // light sampling for it, so no weight).
      if (shading_.sky_level() > 0) lane.L += lane.beta * shading_.sky_L() * scene_.environment->Shape(lane.direction.y());
      return false;
    }
    lane.glow_here = GlowAt(hit);
    // Textures are filtered over the camera ray's footprint; bounces look up
    // a point (zero derivatives: their footprint is the BSDF's, not a pixel's).
    const Shading::Surface surface = shading_.SurfaceAt(
        hit, lane.origin, depth == 0 ? lane.differential : RayDifferential{}, lane.texture_albedo, lane.texture_gloss);
    lane.albedo = surface.albedo;
    lane.gloss = surface.gloss;
    lane.scatters = surface.reflects;  // a glossy coat reflects on black too
    lane.emitter = nullptr;
    if (lane.scatters && !emitters_.empty()) {
      lane.emitter_index = emitters_.Pick(random.Next());
      lane.emitter = &emitters_.entry(lane.emitter_index);
      Prefetch(lane.emitter);
    }
    return true;
  }

  // The second half: the shading normal, the point on the glowing triangle
  // and its MIS weight, the lights' shadow rays, and the glow found here.
  // False: the surface reflects nothing.
  bool ShadeVertex(PathLane& lane, const Hit& hit, int lane_index, int depth,
                   std::vector<LightShadowRay>& light_rays) const {
    SplitMix64& random = *lane.random;
    lane.n_s = hit.front ? hit.normal : Vec3f(-hit.normal);
    const Vec3f& n_s = lane.n_s;
    const GlowTexel glow_here = lane.glow_here;
    const bool scatters = lane.scatters;
    lane.origin_s = hit.position + geometry_.ray_epsilon() * n_s;
    lane.glow_there = {};
    if (lane.emitter) {
      const auto& entry = *lane.emitter;
      float b1, b2;
      const float u1 = random.UniformFloat();
      SampleUniformTriangle(u1, random.UniformFloat(), b1, b2);
      const Vec3f q = entry.v0 + b1 * entry.e1 + b2 * entry.e2;
      // Which sides face each other is decided on the unnormalized
      // direction, so that the branch (taken at random) waits for no square
      // root and a point facing away costs none.
      const Vec3f d = q - hit.position;
      const float d_s = n_s.dot(d), d_front = -entry.normal.dot(d);
      const float d_l = emitters_.two_sided[entry.slot] ? std::abs(d_front) : d_front;  // the side facing us
      if (d_s > 0 && d_l > 0) {
        const float distance2 = d.squaredNorm();
        lane.emitter_distance = std::sqrt(distance2);
        const float inverse_distance = 1.0f / lane.emitter_distance;
        lane.wi = d * inverse_distance;
        const float cos_s = d_s * inverse_distance, cos_l = d_l * inverse_distance;
        lane.glow_there = GlowAt(entry.slot, entry.Texel(solver_->atlas(), b1, b2));
        // f cos / p_light with MIS (power heuristic) against the BSDF's
        // cosine sampling, f = albedo / pi: with p_light = a d^2 / cos_l
        // (a: the area pdf) and p_bsdf = cos_s / pi, the weight over
        // p_light is a d^2 cos_l / ((a d^2)^2 + p_bsdf^2 cos_l^2): one division.
        const float area_term = emitters_.PickedAreaPdf(lane.emitter_index, entry) * distance2;
        if (lane.gloss) {  // f cos kept per band; emitter_scale the weight over p_light
          const GlossyBsdf bsdf(*lane.gloss, lane.albedo->data(), nb_);
          const Vec3f wo = -lane.direction;
          const float p_bsdf = bsdf.Pdf(n_s, wo, lane.wi);
          lane.glow_f_cos.resize(nb_);
          bsdf.Eval(n_s, wo, lane.wi, lane.glow_f_cos.data());
          lane.glow_f_cos *= cos_s;
          lane.emitter_scale = area_term * cos_l / (area_term * area_term + p_bsdf * p_bsdf * cos_l * cos_l);
        } else {
          const float p_bsdf = cos_s * kInvPiF;
          lane.emitter_scale = p_bsdf * area_term * cos_l / (area_term * area_term + p_bsdf * p_bsdf * cos_l * cos_l);
        }
      }
    }
    // Next-event estimation for the lights, when any is on: their shadow
    // rays are cast with the batch's (TracePaths). A delta light has no MIS;
    // an area light's point is weighted against the BSDF's finding it.
    if (scatters)
      for (std::size_t l = 0; l < shading_.lights().size(); ++l) {
        const LightPose& pose = shading_.lights()[l].pose;
        LightRay ray;
        if (pose.area()) {
          const float u1 = random.UniformFloat();
          ray = RayToLight(geometry_, pose, hit.position, n_s, u1, random.UniformFloat());
          const float p_bsdf = !(ray.unit > 0) ? 0.0f
                               : lane.gloss ? GlossyBsdf(*lane.gloss, lane.albedo->data(), nb_)
                                                  .Pdf(n_s, -lane.direction, ray.direction)
                                            : n_s.dot(ray.direction) * kInvPiF;
          ray.unit *= PowerHeuristic(ray.area_pdf, p_bsdf);
        } else {
          ray = RayToLight(geometry_, pose, hit.position, n_s);
        }
        if (ray.unit > 0) light_rays.push_back({lane_index, static_cast<int>(l), &hit, ray});
      }
    // Emission found by the BSDF sample, weighted against light sampling.
    if (glow_here) {
      float weight = 1;
      if (depth > 0) {
        // p_bsdf^2 / (p_bsdf^2 + p_light^2), p_light = a d^2 / cos: one division.
        const float cos_light = -hit.normal.dot(lane.direction);
        const float area_term = emitters_.AreaPdf(hit.object, hit.triangle) * hit.distance * hit.distance;
        const float bsdf_cos = lane.bsdf_pdf * cos_light;
        weight = bsdf_cos * bsdf_cos / (bsdf_cos * bsdf_cos + area_term * area_term);
      }
      for (int c = 0; c < glow_here.band_count; ++c) {
        const int b = glow_here.first_band + c;
        lane.L[b] += lane.beta[b] * glow_here.Lp[c] * weight;
      }
    }
    return scatters;
  }

  // The next direction: cosine sampling of the diffuse BSDF (f cos / pdf =
  // albedo), then Russian roulette from the fourth bounce. False: it ends.
  bool ContinuePath(PathLane& lane, int depth) const {
    SplitMix64& random = *lane.random;
    if (lane.gloss) {
      // The glossy BSDF's own sampling: beta *= f cos / pdf.
      const GlossyBsdf bsdf(*lane.gloss, lane.albedo->data(), nb_);
      const Vec3f wo = -lane.direction;
      const float u0 = random.UniformFloat(), u1 = random.UniformFloat(), u2 = random.UniformFloat();
      Vec3f wi;
      float pdf;
      if (!bsdf.Sample(lane.n_s, wo, u0, u1, u2, &wi, &pdf)) return false;
      Bands f(nb_);
      bsdf.Eval(lane.n_s, wo, wi, f.data());
      lane.beta *= f * (lane.n_s.dot(wi) / pdf);
      lane.direction = wi;
      lane.bsdf_pdf = pdf;
      lane.origin = lane.origin_s;
    } else {
      lane.direction = SampleCosineHemisphere(TangentFrame(lane.n_s), random);
      lane.bsdf_pdf = lane.n_s.dot(lane.direction) * kInvPiF;
      lane.origin = lane.origin_s;
      lane.beta *= *lane.albedo;
    }
    if (depth >= 3) {  // Russian roulette keeps the estimate unbiased
      const float survive = std::min(1.0f, lane.beta.maxCoeff());
      if (random.UniformFloat() >= survive) return false;
      lane.beta /= survive;
    }
    return true;
  }



  // A thread's row state, kept from row to row.
  struct PathRow {
    std::vector<SplitMix64> streams;
    std::vector<Bands> sums;
    Wavefront wave;
  };
  const Shading& shading_;
  const CameraRays& camera_;
  const SceneGeometry& geometry_;
  const Scene& scene_;
  const CoupledSolver* solver_;
  const VolumeMedia* media_;
  const FrameOptions& options_;
  int nb_;
  std::shared_ptr<const EmitterBlocks> blocks_;  // null: the glowing triangles are chosen one by one
  FrameGlow glow_;
  EmitterDistribution emitters_;  // after the glow, which it reads
  bool prefetch_emitters_ = false;  // PrefetchEmitterPicks
  tbb::enumerable_thread_specific<PathRow> rows_;
};

}  // namespace

std::unique_ptr<FrameTransport> MakePathTransport(const Shading& shading, const CameraRays& camera) {
  return std::make_unique<PathTransport>(shading, camera);
}

}  // namespace phos::render
