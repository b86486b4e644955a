#pragma once
// The one random-number generator of the renderer and its baselines, and the
// one per-pixel noise. SplitMix64 (Steele, Lea and Flood 2014): a state of one
// word, well mixed, so every pixel, sample and texel can have a stream of its
// own from a seed made of its indices, and a render is the same on any number
// of threads. The simulators (model/synthetic, the simulated lab) draw from
// std::mt19937_64 through <random>'s distributions instead: long streams,
// exactly reproducible on every machine.

#include <cmath>
#include <cstdint>

namespace phos {

class SplitMix64 {
 public:
  explicit SplitMix64(std::uint64_t state) : state_(state) {}
  std::uint64_t Next() { return Mix(state_ += kGolden); }
  // What Next() will return after `skip` more draws, without drawing: a
  // consumer that knows its next draws can fetch what they will index. The
  // state is a counter, so that is one step of it.
  std::uint64_t Peek(int skip = 0) const {
    return Mix(state_ + static_cast<std::uint64_t>(skip + 1) * kGolden);
  }
  // Uniform in [0, 1): 24 bits for a float, 53 for a double (every value exact).
  float UniformFloat() { return ToUniformFloat(Next()); }
  double UniformDouble() { return static_cast<double>(Next() >> 11) * 0x1.0p-53; }

  // The finaliser (Stafford's Mix13): every bit of the output depends on
  // every bit of the input. Hash01 uses it too.
  static std::uint64_t Mix(std::uint64_t z) {
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }
  // A word's top 24 bits as a float in [0, 1), every value exact.
  static float ToUniformFloat(std::uint64_t word) { return static_cast<float>(word >> 40) * (1.0f / 16777216.0f); }

 private:
  static constexpr std::uint64_t kGolden = 0x9E3779B97F4A7C15ull;
  std::uint64_t state_;
};

// A reproducible uniform number in [0, 1) from three integers, without a
// stream: SplitMix64's finaliser on a mix of them.
inline float Hash01(std::uint64_t a, std::uint64_t b, std::uint64_t c) {
  const std::uint64_t x =
      a * 0x9E3779B97F4A7C15ull ^ (b + 0x632BE59BD9B4E019ull) * 0xBF58476D1CE4E5B9ull ^ c * 0x94D049BB133111EBull;
  return SplitMix64::ToUniformFloat(SplitMix64::Mix(x));
}

// Interleaved gradient noise (Jimenez 2014), in [0, 1): a fixed per-pixel
// offset whose neighbours differ, so one sample per pixel shows fine noise,
// not banding.
inline float InterleavedGradientNoise(int x, int y) {
  // a - floor(a) is fmod(a, 1) for the a >= 0 of pixel indices, exactly,
  // at a tenth of its cost (fmodf was 2.6% of a direct frame).
  const float a = 0.06711056f * static_cast<float>(x) + 0.00583715f * static_cast<float>(y);
  const float v = 52.9829189f * (a - std::floor(a));
  return v - std::floor(v);
}

}  // namespace phos
