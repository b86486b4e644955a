// Writes fixtures/materials/two-state-*.json and the many-trap fixtures
// (sign-paint.json) from the specs in model/synthetic.h
// (TwoStateFixtureSpecs, ManyTrapFixtureSpecs), so the origin of every
// synthetic fixture is this program and its stated parameters, not a hand edit.
//   build/bin/phos-two-state-fixtures --out fixtures/materials
// With --random N it writes N random ones instead (RandomTwoStateMaterial,
// seeds --seed .. --seed + N - 1), for checks on materials no test saw.
// tests/model/synthetic_test.cpp checks that the files are what it writes.

#include <cstdio>
#include <filesystem>

#include <CLI/CLI.hpp>

#include "phos/model/material.h"
#include "phos/model/synthetic.h"

int main(int argc, char** argv) {
  CLI::App app{"Writes the two-state fixture materials (synthetic, from model/synthetic.h)"};
  std::string out = "fixtures/materials";
  int random = 0;
  std::uint64_t seed = 1;
  app.add_option("--out", out, "folder to write into")->capture_default_str();
  app.add_option("--random", random, "write this many random two-state materials instead of the fixtures")
      ->capture_default_str();
  app.add_option("--seed", seed, "first seed of --random")->capture_default_str();
  CLI11_PARSE(app, argc, argv);
  std::vector<phos::TwoStateSpec> specs = phos::TwoStateFixtureSpecs();
  if (random > 0) {
    specs.clear();
    for (int i = 0; i < random; ++i) specs.push_back(phos::RandomTwoStateSpec(seed + static_cast<std::uint64_t>(i)));
  }
  std::filesystem::create_directories(out);
  for (const phos::TwoStateSpec& spec : specs) {
    const std::filesystem::path path = std::filesystem::path(out) / (spec.name + ".json");
    phos::SaveMaterial(phos::TwoStateMaterial(spec), path);
    std::printf("wrote %s\n", path.string().c_str());
  }
  if (random > 0) return 0;
  for (const phos::ManyTrapSpec& spec : phos::ManyTrapFixtureSpecs()) {
    const std::filesystem::path path = std::filesystem::path(out) / (spec.name + ".json");
    phos::SaveMaterial(phos::ManyTrapMaterial(spec), path);
    std::printf("wrote %s\n", path.string().c_str());
  }
  return 0;
}
