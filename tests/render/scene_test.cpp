// Scenes, meshes and the texel atlas: loading, validation with clear errors,
// and the atlas's addressing (a bijection that partitions each triangle).

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <random>
#include <set>

#include <sys/stat.h>

#include <nlohmann/json.hpp>

#include "phos/render/geometry.h"
#include "phos/render/solver.h"
#include "phos/render/scene.h"
#include "phos/render/subsurface.h"
#include "phos/render/volume.h"
#include "phos/util/error.h"
#include "phos/util/json.h"
#include "render/scene_util.h"
#include "test_util.h"

namespace phos::render {
namespace {

using phos::testing::ErrorOfType;
using phos::testing::Fixture;

TEST(SubTriangles, IndexAndCentreAreInverse) {
  for (int m = 1; m <= 24; ++m) {
    std::set<int> seen;
    for (int k = 0; k < m * m; ++k) {
      float b1, b2;
      SubTriangleCenter(m, k, b1, b2);
      ASSERT_GT(b1, 0);
      ASSERT_GT(b2, 0);
      ASSERT_LT(b1 + b2, 1);
      ASSERT_EQ(SubTriangleIndex(m, b1, b2), k) << "m " << m;
      seen.insert(k);
    }
    EXPECT_EQ(static_cast<int>(seen.size()), m * m);
  }
}

TEST(SubTriangles, PartitionTheTriangleIntoEqualAreas) {
  // Uniform points on the triangle fall into each of the m^2 texels equally often.
  const int m = 5, samples = 200000;
  std::vector<int> count(m * m, 0);
  std::mt19937 random(3);
  std::uniform_real_distribution<float> u(0, 1);
  for (int s = 0; s < samples; ++s) {
    float b1 = u(random), b2 = u(random);
    if (b1 + b2 > 1) b1 = 1 - b1, b2 = 1 - b2;
    const int k = SubTriangleIndex(m, b1, b2);
    ASSERT_GE(k, 0);
    ASSERT_LT(k, m * m);
    ++count[k];
  }
  const double expected = double(samples) / (m * m);
  for (int k = 0; k < m * m; ++k) EXPECT_NEAR(count[k], expected, 5 * std::sqrt(expected)) << "texel " << k;
  // Corners and edges stay in range.
  EXPECT_EQ(SubTriangleIndex(m, 0, 0), 0);
  EXPECT_LT(SubTriangleIndex(m, 1, 0), m * m);
  EXPECT_LT(SubTriangleIndex(m, 0, 1), m * m);
  EXPECT_LT(SubTriangleIndex(m, 0.5f, 0.5f), m * m);
}

TEST(Shapes, FrontsFaceOutwardOrInwardAsAsked) {
  for (bool inward : {false, true}) {
    for (const Mesh& mesh : {MakeBox(Vec3(1, 2, 3), inward), MakeSphere(2.0, 2, inward)}) {
      for (const Eigen::Vector3i& t : mesh.triangles) {
        const Eigen::Vector3f a = mesh.positions[t[0]], b = mesh.positions[t[1]], c = mesh.positions[t[2]];
        const float outward = (b - a).cross(c - a).dot((a + b + c) / 3);
        EXPECT_EQ(outward < 0, inward) << mesh.source;
      }
    }
  }
  const Mesh quad = MakeQuad(2, 3);
  const Eigen::Vector3f n = (quad.positions[2] - quad.positions[0]).cross(quad.positions[1] - quad.positions[0]);
  EXPECT_GT(n.y(), 0);
}

TEST(Meshes, CornellWallsFaceIntoTheBox) {
  const Eigen::Vector3f centre(0.278f, 0.274f, 0.28f);
  for (const std::string group : {"floor", "ceiling", "back", "left", "right"}) {
    const Mesh mesh = LoadMesh(Fixture("scenes/meshes/cornell.obj"), group, "test");
    ASSERT_EQ(mesh.triangles.size(), 2u) << group;
    for (const Eigen::Vector3i& t : mesh.triangles) {
      const Eigen::Vector3f a = mesh.positions[t[0]];
      const Eigen::Vector3f n = (mesh.positions[t[1]] - a).cross(mesh.positions[t[2]] - a);
      EXPECT_GT(n.dot(centre - a), 0) << group;
    }
  }
  EXPECT_EQ(LoadMesh(Fixture("scenes/meshes/cornell.obj"), "tall_block", "test").triangles.size(), 10u);
  EXPECT_NE(ErrorOfType<UserError>([] {
              LoadMesh(Fixture("scenes/meshes/cornell.obj"), "sofa", "scene.json");
            }).find("no group 'sofa'"),
            std::string::npos);
}

TEST(Meshes, GltfNodeTransformsAreApplied) {
  const Mesh mesh = LoadMesh(Fixture("scenes/meshes/pedestal.gltf"), "", "test");
  ASSERT_EQ(mesh.triangles.size(), 12u);
  Eigen::AlignedBox3f box;
  for (const auto& p : mesh.positions) box.extend(p);
  // A unit cube, translated by 0.5 in y and scaled 2x in y: y spans [-0.5, 1.5].
  EXPECT_NEAR(box.min().y(), -0.5f, 1e-6);
  EXPECT_NEAR(box.max().y(), 1.5f, 1e-6);
  EXPECT_NEAR(box.max().x(), 0.5f, 1e-6);
  for (const Eigen::Vector3i& t : mesh.triangles) {  // still outward after the transform
    const Eigen::Vector3f a = mesh.positions[t[0]], b = mesh.positions[t[1]], c = mesh.positions[t[2]];
    EXPECT_GT((b - a).cross(c - a).dot((a + b + c) / 3 - Eigen::Vector3f(0, 0.5f, 0)), 0);
  }
}

// What of a glTF material phos does not draw is listed by field, once each
// however many primitives share the material (phos render warns of it); a
// material of base colour and metallic-roughness alone lists nothing.
TEST(Meshes, GltfMaterialPartsPhosDoesNotDrawAreListedOnce) {
  const std::filesystem::path dir = std::filesystem::path(::testing::TempDir()) / "unread";
  std::filesystem::create_directories(dir);
  std::filesystem::copy_file(Fixture("scenes/textured/checker.png"), dir / "checker.png",
                             std::filesystem::copy_options::overwrite_existing);
  nlohmann::json gltf = ReadJsonFile(Fixture("scenes/textured/plane.gltf"));
  std::ofstream(dir / "plain.gltf") << gltf.dump();
  EXPECT_TRUE(LoadMesh(dir / "plain.gltf", "", "test").unread_material.empty());
  nlohmann::json& material = gltf["materials"][0];
  material["normalTexture"] = {{"index", 0}, {"scale", 0.5}};
  material["occlusionTexture"] = {{"index", 0}};
  material["emissiveTexture"] = {{"index", 0}};
  material["emissiveFactor"] = {1, 0.5, 0};
  material["alphaMode"] = "MASK";
  material["doubleSided"] = true;
  material["extensions"] = {{"KHR_materials_emissive_strength", {{"emissiveStrength", 5}}}};
  gltf["extensionsUsed"] = {"KHR_materials_emissive_strength"};
  gltf["meshes"][0]["primitives"].push_back(gltf["meshes"][0]["primitives"][0]);  // the same material twice
  std::ofstream(dir / "rich.gltf") << gltf.dump();
  const Mesh mesh = LoadMesh(dir / "rich.gltf", "", "test");
  EXPECT_EQ(mesh.unread_material,
            (std::vector<std::string>{"materials[0].normalTexture", "materials[0].occlusionTexture",
                                      "materials[0].emissiveTexture", "materials[0].emissiveFactor",
                                      "materials[0].alphaMode MASK", "materials[0].doubleSided",
                                      "materials[0].extensions.KHR_materials_emissive_strength"}));
  // A black emissive factor and an opaque alpha are what glTF means by none.
  material = ReadJsonFile(Fixture("scenes/textured/plane.gltf"))["materials"][0];
  material["emissiveFactor"] = {0, 0, 0};
  material["alphaMode"] = "OPAQUE";
  gltf.erase("extensionsUsed");
  std::ofstream(dir / "opaque.gltf") << gltf.dump();
  EXPECT_TRUE(LoadMesh(dir / "opaque.gltf", "", "test").unread_material.empty());
}

TEST(Scenes, EveryFixtureLoads) {
  int count = 0;
  for (const auto& entry : std::filesystem::directory_iterator(Fixture("scenes"))) {
    if (entry.path().extension() != ".json") continue;
    const Scene scene = LoadScene(entry.path());
    EXPECT_FALSE(scene.objects.empty()) << entry.path();
    EXPECT_TRUE(scene.HasPhosphors()) << entry.path();
    ++count;
  }
  EXPECT_GE(count, 3);
}

// Loads the Cornell fixture with one change and returns the error it gives.
std::string ErrorAfterEdit(const std::function<void(nlohmann::json&)>& edit) {
  nlohmann::json json = ReadJsonFile(Fixture("scenes/cornell-phosphor.json"));
  edit(json);
  return ErrorOfType<UserError>([&] { SceneFromJson(json, Fixture("scenes"), "cornell-phosphor.json"); });
}

// Loads the dust-sheets fixture (volumes, sheet lights) with one change.
std::string MediaErrorAfterEdit(const std::function<void(nlohmann::json&)>& edit) {
  nlohmann::json json = ReadJsonFile(Fixture("scenes/dust-sheets.json"));
  edit(json);
  return ErrorOfType<UserError>([&] { SceneFromJson(json, Fixture("scenes"), "dust-sheets.json"); });
}

TEST(Scenes, VolumesAndSheetsLoadAndBadOnesNameTheField) {
  const Scene scene = LoadScene(Fixture("scenes/dust-sheets.json"));
  ASSERT_EQ(scene.volumes.size(), 1u);
  const Volume& dust = scene.volumes[0];
  EXPECT_EQ(dust.voxel_count(), 48u * 28 * 32);
  EXPECT_TRUE(dust.phosphor != nullptr);
  // The ellipsoid leaves its corners empty; the puffs vary inside.
  EXPECT_EQ(dust.density[0], 0.0f);
  const float max_density = *std::max_element(dust.density.begin(), dust.density.end());
  EXPECT_GT(max_density, 0.5f);
  EXPECT_LE(max_density, 1.0f);
  EXPECT_EQ(scene.lights[0].kind, Light::Kind::kSheet);
  EXPECT_TRUE(scene.HasPhosphors());

  EXPECT_EQ(MediaErrorAfterEdit([](nlohmann::json&) {}), "(no error)");
  auto error_has = [](const std::string& error, const std::string& part) {
    return error.find(part) != std::string::npos;
  };
  EXPECT_TRUE(error_has(MediaErrorAfterEdit([](nlohmann::json& j) {
                          j["volumes"][0]["bounds"]["max"] = {-1, 1, 1};
                        }),
                        "volumes[0].bounds.max"));
  EXPECT_TRUE(error_has(MediaErrorAfterEdit([](nlohmann::json& j) {
                          j["volumes"][0]["resolution"] = {4, 4};
                        }),
                        "resolution"));
  EXPECT_TRUE(error_has(MediaErrorAfterEdit([](nlohmann::json& j) {
                          j["volumes"][0]["density"] = {1, 2, 3};
                        }),
                        "density"));
  EXPECT_TRUE(error_has(MediaErrorAfterEdit([](nlohmann::json& j) { j["volumes"][0]["density"]["shape"] = "torus"; }),
                        "torus"));
  EXPECT_TRUE(error_has(MediaErrorAfterEdit([](nlohmann::json& j) { j["volumes"][0]["g"] = 1.0; }), "volumes[0].g"));
  EXPECT_TRUE(error_has(MediaErrorAfterEdit([](nlohmann::json& j) { j["volumes"][0]["sigma_t_per_m"] = -1; }),
                        "sigma_t_per_m"));
  EXPECT_TRUE(error_has(MediaErrorAfterEdit([](nlohmann::json& j) {
                          j["volumes"][0].erase("albedo");
                          j["volumes"][0].erase("phosphor");
                        }),
                        "albedo"));
  EXPECT_TRUE(
      error_has(MediaErrorAfterEdit([](nlohmann::json& j) { j["lights"][0]["thickness_m"] = 0; }), "thickness_m"));
  EXPECT_TRUE(error_has(MediaErrorAfterEdit([](nlohmann::json& j) {
                          j["lights"][0]["normal"] = {0, 0, 0};
                        }),
                        "normal"));
  EXPECT_TRUE(error_has(MediaErrorAfterEdit([](nlohmann::json& j) { j["lights"][0]["type"] = "point"; }),
                        "only a sheet light"));
}

TEST(Scenes, TranslucentObjectsTakeTheDipolesReflectanceAsAlbedo) {
  const Scene scene = LoadScene(Fixture("scenes/translucent-shadow.json"));
  const Object& wax = scene.objects[1];
  ASSERT_TRUE(wax.subsurface.has_value());
  for (int b = 0; b < 8; ++b)
    EXPECT_DOUBLE_EQ(wax.albedo[b], Dipole::From(wax.subsurface->sigma_a_per_m[b],
                                                 wax.subsurface->sigma_s_prime_per_m[b], wax.subsurface->eta)
                                        .TotalReflectance());
  EXPECT_LT(wax.albedo[0], wax.albedo[7]);  // absorbs blue: a warm wax
  auto edit = [](const std::function<void(nlohmann::json&)>& change) {
    nlohmann::json json = ReadJsonFile(Fixture("scenes/translucent-shadow.json"));
    change(json);
    return ErrorOfType<UserError>([&] { SceneFromJson(json, Fixture("scenes"), "translucent-shadow.json"); });
  };
  EXPECT_NE(edit([](nlohmann::json& j) { j["objects"][1]["albedo"] = 0.5; }).find("objects[1].albedo"),
            std::string::npos);
  EXPECT_NE(edit([](nlohmann::json& j) { j["objects"][1]["subsurface"]["sigma_a_per_m"] = 0; }).find("sigma_a_per_m"),
            std::string::npos);
  EXPECT_NE(edit([](nlohmann::json& j) { j["objects"][1]["subsurface"]["eta"] = 0.5; }).find("eta"), std::string::npos);
  EXPECT_NE(edit([](nlohmann::json& j) { j["objects"][1]["subsurface"]["g"] = 0.5; }).find("subsurface"),
            std::string::npos);
}

TEST(Scenes, TheSkyLoadsAndBadOnesNameTheField) {
  const Scene scene = LoadScene(Fixture("scenes/dusk-sign.json"));
  ASSERT_TRUE(scene.environment.has_value());
  EXPECT_DOUBLE_EQ(scene.environment->gradient, 0.6);
  EXPECT_EQ(scene.environment->schedule.LevelAt(70), 0.0);
  auto edit = [](const std::function<void(nlohmann::json&)>& change) {
    nlohmann::json json = ReadJsonFile(Fixture("scenes/dusk-sign.json"));
    change(json);
    return ErrorOfType<UserError>([&] { SceneFromJson(json, Fixture("scenes"), "dusk-sign.json"); });
  };
  EXPECT_EQ(edit([](nlohmann::json&) {}), "(no error)");
  EXPECT_NE(edit([](nlohmann::json& j) { j["environment"]["gradient"] = 2; }).find("environment.gradient"),
            std::string::npos);
  EXPECT_NE(edit([](nlohmann::json& j) { j["environment"]["radiance"] = -1; }).find("environment.radiance"),
            std::string::npos);
  EXPECT_NE(edit([](nlohmann::json& j) { j["environment"]["colour"] = 1; }).find("colour"), std::string::npos);
  EXPECT_NE(edit([](nlohmann::json& j) { j["environment"]["schedule"] = nlohmann::json::array(); }).find("schedule"),
            std::string::npos);
}

TEST(Scenes, BadInputNamesTheFileAndField) {
  EXPECT_EQ(ErrorAfterEdit([](nlohmann::json&) {}), "(no error)");
  EXPECT_NE(ErrorAfterEdit([](nlohmann::json& j) { j["lights"][0]["colour"] = 1; }).find("lights[0]"),
            std::string::npos);
  EXPECT_NE(ErrorAfterEdit([](nlohmann::json& j) { j["objects"][2]["mesh"] = "missing.obj"; }).find("does not exist"),
            std::string::npos);
  EXPECT_NE(ErrorAfterEdit([](nlohmann::json& j) { j["objects"][0]["albedo"] = 1.5; }).find("objects[0].albedo"),
            std::string::npos);
  EXPECT_NE(ErrorAfterEdit([](nlohmann::json& j) {
              j["objects"][0]["albedo"] = {0.5, 0.5};
            }).find("objects[0].albedo"),
            std::string::npos);
  EXPECT_NE(ErrorAfterEdit([](nlohmann::json& j) {
              j["lights"][0]["spectrum"]["type"] = "laser";
            }).find("unknown spectrum type 'laser'"),
            std::string::npos);
  EXPECT_NE(ErrorAfterEdit([](nlohmann::json& j) {
              j["lights"][0]["schedule"] = {{{"t_s", 5}, {"level", 1}}, {{"t_s", 2}, {"level", 0}}};
            }).find("keyframe times must increase"),
            std::string::npos);
  EXPECT_NE(ErrorAfterEdit([](nlohmann::json& j) {
              j["objects"][0]["initial"] = "equilibrium";
            }).find("only a phosphorescent object"),
            std::string::npos);
  EXPECT_NE(ErrorAfterEdit([](nlohmann::json& j) {
              j["objects"][0]["two_sided"] = true;
            }).find("objects[0].two_sided: only a phosphor is one- or two-sided"),
            std::string::npos);
  EXPECT_NE(ErrorAfterEdit([](nlohmann::json& j) {
              j["objects"][2]["two_sided"] = "yes";
            }).find("objects[2].two_sided: expected true or false"),
            std::string::npos);
  EXPECT_EQ(ErrorAfterEdit([](nlohmann::json& j) { j["objects"][2]["two_sided"] = true; }), "(no error)");
  EXPECT_NE(ErrorAfterEdit([](nlohmann::json& j) { j["schema"] = "phos.scene/2"; }).find("schema"), std::string::npos);
  EXPECT_NE(
      ErrorAfterEdit([](nlohmann::json& j) { j["camera"]["look_at"] = j["camera"]["position"]; }).find("must differ"),
      std::string::npos);
  EXPECT_NE(ErrorAfterEdit([](nlohmann::json& j) {
              j["bands_nm"] = {400, 500, 600, 700};
            })
                .find("the material's bands_nm [400, 437.5, 475, 512.5, 550, 587.5, 625, 662.5, 700] nm differ from "
                      "the scene's [400, 500, 600, 700] nm; the renderer needs one band grid: give the scene the "
                      "material's bands_nm, or make the material on the scene's"),
            std::string::npos);
  // Bounds as written (the float bound read [0.019999999552965164, 1]).
  EXPECT_NE(ErrorAfterEdit([](nlohmann::json& j) {
              j["objects"][0]["roughness"] = 0.01;
            }).find("objects[0].roughness: expected a number in [0.02, 1], got 0.01"),
            std::string::npos);
  EXPECT_EQ(ErrorAfterEdit([](nlohmann::json& j) { j["objects"][0]["roughness"] = 0.02; }), "(no error)");
  // A file that is not there is named at its field, with the folder it was looked in.
  const std::string no_material =
      ErrorAfterEdit([](nlohmann::json& j) { j["objects"][2]["phosphor"] = "../materials/none.json"; });
  EXPECT_NE(no_material.find("objects[2].phosphor: phosphor file '"), std::string::npos) << no_material;
  EXPECT_NE(no_material.find("none.json' does not exist or is not a regular file (a scene's paths are relative to "
                             "its own folder, "),
            std::string::npos)
      << no_material;
  EXPECT_NE(no_material.find((testing::Fixture("scenes").lexically_normal().string() + ")")), std::string::npos)
      << no_material;
  EXPECT_NE(ErrorAfterEdit([](nlohmann::json& j) {
              j["objects"][0]["mesh"] = "meshes/nothing.obj";
            }).find("objects[0].mesh: mesh file '"),
            std::string::npos);
}

TEST(Scenes, RigidMotionInterpolatesAndHolds) {
  RigidMotion motion;
  RigidKey a, b;
  a.t_s = 0;
  b.t_s = 10;
  b.translate = Vec3(10, 0, 0);
  b.rotate = Eigen::Quaterniond(Eigen::AngleAxisd(M_PI / 2, Vec3::UnitY()));
  motion.keys = {a, b};
  EXPECT_TRUE(motion.Moves());
  EXPECT_TRUE((motion.At(5) * Vec3(0, 0, 0)).isApprox(Vec3(5, 0, 0)));
  EXPECT_TRUE((motion.At(-3) * Vec3(1, 0, 0)).isApprox(Vec3(1, 0, 0)));
  EXPECT_TRUE((motion.At(30) * Vec3(1, 0, 0)).isApprox(Vec3(10, 0, -1), 1e-12));
  EXPECT_FALSE(motion.MovesBetween(10, 20));
  EXPECT_TRUE(motion.MovesBetween(9, 20));
}

TEST(Atlas, OnlyPhosphorsCarryTexelsOfTheAskedSize) {
  Scene scene = phos::testing::EmptyScene();
  scene.objects.push_back(phos::testing::MakeObject("plain", MakeQuad(1, 1), 0.5));
  scene.objects.push_back(phos::testing::MakeObject(
      "glowing", MakeQuad(1, 1), 0.5,
      phos::testing::UniformPhosphor(0.1, std::vector<double>(8, 0.1), std::vector<double>(8, 1))));
  scene.objects[1].texel_size_m = 0.1;
  SceneGeometry geometry(scene);
  TexelAtlas atlas(scene, geometry);
  EXPECT_EQ(atlas.SlotOf(0), -1);
  ASSERT_EQ(atlas.SlotOf(1), 0);
  // Two triangles whose longest edge is the diagonal sqrt(2): m = ceil(14.14) = 15.
  EXPECT_EQ(atlas.objects()[0].m[0], 15);
  EXPECT_EQ(atlas.total_texels(), 2u * 15 * 15);
  // CountTexels, which the loader checks the limits with, counts what the atlas lays out.
  EXPECT_EQ(CountTexels(scene), (std::vector<std::size_t>{0, 2u * 15 * 15}));
}

// What a scene's memory grows with is counted when it loads (so render
// --check refuses it too), before anything is allocated: 4 phosphor quads of
// 1e6 m at texel_size_m 1e-3 (1.1 KB) passed the loader and then asked for
// 134 million texels (6.4 GiB, "internal error: std::bad_alloc"); 10,000
// lights took 3.2 GiB and 5,000 phosphor spheres 3.9 GiB.
TEST(Scenes, WhatMemoryGrowsWithIsCountedAtLoadAndRefusedPastItsLimit) {
  auto one_line = [](const std::string& error, const std::string& start) {
    EXPECT_EQ(error.find('\n'), std::string::npos) << error;
    EXPECT_EQ(error.rfind(start, 0), 0u) << error;
  };
  // Each quad: two triangles whose longest edge (the diagonal) is cut into 4096 texels.
  one_line(ErrorAfterEdit([](nlohmann::json& j) {
             j["texel_size_m"] = 1e-3;
             j["objects"] = nlohmann::json::array();
             for (int i = 0; i < 4; ++i)
               j["objects"].push_back({{"name", "quad " + std::to_string(i)},
                                       {"shape", {{"type", "quad"}, {"size", {1e6, 1e6}}}},
                                       {"albedo", 0.5},
                                       {"phosphor", "../materials/green.json"}});
           }),
           "cornell-phosphor.json: texel_size_m: the phosphors would have " + std::to_string(4 * 2 * 4096 * 4096) +
               " texels ('quad 0' " + std::to_string(2 * 4096 * 4096) + " of them), more than the limit of " +
               std::to_string(kMaxTexels) + "; choose a larger texel size");
  one_line(ErrorAfterEdit([](nlohmann::json& j) { j["objects"][2]["texel_size_m"] = 1e-4; }),
           "cornell-phosphor.json: objects[2].texel_size_m: the phosphors would have ");
  // Texels times lights: the solver keeps each light's irradiance per texel.
  auto with_lights = [](int n) {
    return [n](nlohmann::json& j) {
      j["texel_size_m"] = 1e-3;
      const nlohmann::json light = j["lights"][0];
      for (int i = 1; i < n; ++i) j["lights"].push_back(light), j["lights"].back()["name"] = "led " + std::to_string(i);
    };
  };
  const Scene few = [&] {
    nlohmann::json json = ReadJsonFile(Fixture("scenes/cornell-phosphor.json"));
    with_lights(1)(json);
    return SceneFromJson(json, Fixture("scenes"), "cornell-phosphor.json");
  }();
  std::size_t texels = 0;
  for (std::size_t n : CountTexels(few)) texels += n;
  const int lights_past = static_cast<int>(kMaxTexelLights / texels) + 1;
  ASSERT_LE(lights_past, static_cast<int>(kMaxLights));
  one_line(ErrorAfterEdit(with_lights(lights_past)), "cornell-phosphor.json: texel_size_m: the phosphors would have " +
                                                         std::to_string(texels) + " texels ('left wall' ");
  EXPECT_NE(ErrorAfterEdit(with_lights(lights_past)).find("times " + std::to_string(lights_past) + " lights more"),
            std::string::npos);
  EXPECT_EQ(ErrorAfterEdit(with_lights(lights_past - 1)), "(no error)");
  // Lights and objects by number, before any of them is read.
  one_line(ErrorAfterEdit([](nlohmann::json& j) {
             for (int i = 0; i < 5000; ++i) j["lights"].push_back(j["lights"][0]);
           }),
           "cornell-phosphor.json: lights: has 5001 lights, more than the limit of 4096 lights");
  one_line(ErrorAfterEdit([](nlohmann::json& j) {
             for (int i = 0; i < 5000; ++i) j["objects"].push_back({{"name", std::to_string(i)}});
           }),
           "cornell-phosphor.json: objects: has 5007 objects, more than the limit of 1024");
  // Triangles over all objects: 52 spheres of 20 x 4^7 triangles, 2^24 passed at the 52nd.
  one_line(ErrorAfterEdit([](nlohmann::json& j) {
             j["objects"] = nlohmann::json::array();
             for (int i = 0; i < 52; ++i)
               j["objects"].push_back({{"name", std::to_string(i)},
                                       {"shape", {{"type", "sphere"}, {"radius", 0.1}, {"subdivisions", 7}}},
                                       {"albedo", 0.5}});
           }),
           "cornell-phosphor.json: objects[51]: the scene's objects up to this one have 17039360 triangles, more "
           "than the limit of 16777216");
}

}  // namespace
}  // namespace phos::render

namespace phos::render {
namespace {

TEST(UvAtlas, TexelsFollowTheMeshsUvMapAndOnlyCoveredOnesCarryState) {
  Scene scene = phos::testing::EmptyScene();
  Object tile = phos::testing::MakeObject(
      "tile", LoadMesh(phos::testing::Fixture("scenes/meshes/tile.obj"), "", "test"), 0.5,
      phos::testing::UniformPhosphor(0.1, std::vector<double>(8, 0.1), std::vector<double>(8, 1)));
  ASSERT_TRUE(tile.mesh->has_uvs());
  tile.texel_size_m = 0.05;
  scene.objects.push_back(tile);
  SceneGeometry geometry(scene);
  TexelAtlas atlas(scene, geometry);
  const TexelAtlas::ObjectTexels& texels = atlas.objects()[0];
  ASSERT_TRUE(texels.uv());
  // 1 m^2 on a quarter of UV space: 2 m per UV unit, 0.05 m texels -> 40 per UV unit;
  // the tile covers 20 x 20 of them, and only those carry a state.
  EXPECT_EQ(texels.uv_resolution, 40);
  EXPECT_EQ(texels.count, 400u);
  // Every texel's anchor lies on the tile, inside its own UV cell, and hits map back to it.
  atlas.ForEachTexel(0, [&](std::size_t k, int t, float b1, float b2) {
    const Eigen::Vector3f p = geometry.Point(0, t, b1, b2);
    EXPECT_LE(std::abs(p.x()), 0.5f + 1e-6f);
    EXPECT_EQ(atlas.TexelOf(0, t, b1, b2), k);
  });
  // A point at (x, z) = (0.325, -0.175) has UV ((x + 0.5) / 2, (z + 0.5) / 2) = (0.4125, 0.1625): the
  // centre of cell (16, 6). (A point on a cell's corner, as (0.3, -0.2) is, falls on either side with
  // the last bit of Embree's float barycentrics, which differ between its AVX2 and AVX-512 kernels.)
  const Hit hit = geometry.Intersect(Eigen::Vector3f(0.325f, 1, -0.175f), Eigen::Vector3f(0, -1, 0));
  ASSERT_TRUE(hit);
  EXPECT_EQ(static_cast<std::int32_t>(atlas.TexelOf(0, hit.triangle, hit.b1, hit.b2)), texels.uv_index[6 * 40 + 16]);
  // "auto" overrides the map.
  scene.objects[0].texels = "auto";
  TexelAtlas automatic(scene, geometry);
  EXPECT_FALSE(automatic.objects()[0].uv());
}

TEST(UvAtlas, SolverChargesUvTexelsLikeTheClosedForm) {
  Scene scene = phos::testing::EmptyScene();
  Object tile = phos::testing::MakeObject(
      "tile", LoadMesh(phos::testing::Fixture("scenes/meshes/tile.obj"), "", "test"), 0.5,
      phos::testing::UniformPhosphor(0.1, {1, 0, 0, 0, 0, 0, 0, 0}, {0, 0, 0, 1, 0, 0, 0, 0}));
  tile.texel_size_m = 0.1;
  scene.objects.push_back(tile);
  scene.lights.push_back(phos::testing::PointLight(Vec3(0, 1, 0), {1, 0, 0, 0, 0, 0, 0, 0}));
  SceneGeometry geometry(scene);
  CoupledSolver solver(scene, geometry);
  solver.AdvanceTo(2.0);
  // Under the light: E = 1 / 1^2 at the centre; texel centres lie within 0.05 m of it.
  const Hit hit = geometry.Intersect(Eigen::Vector3f(0.01f, 1, 0.01f), Eigen::Vector3f(0, -1, 0));
  const std::size_t texel = solver.atlas().TexelOf(0, hit.triangle, hit.b1, hit.b2);
  const double E = solver.TexelIrradiance(0, texel)[0];
  EXPECT_GT(E, 0.99);
  EXPECT_LE(E, 1.0);
  const double r = E / (E + 0.1) * -std::expm1(-(E + 0.1) * 2.0);
  EXPECT_NEAR(solver.State(0, 0, texel), r, 1e-5);
}

// Found by mutating the fixtures (docs/fuzzing.md): each input that crashed, hung or
// ran out of memory is refused at load time in one line naming the field
// and the limit.
TEST(Scenes, CoordinatesTimesAndCountsOutsideTheLimitsAreRefused) {
  auto error_has = [](const std::string& error, const std::string& part) {
    EXPECT_EQ(error.find('\n'), std::string::npos) << error;
    return error.find(part) != std::string::npos;
  };
  // Embree's assertion in bvh_intersector1.cpp aborted on these.
  EXPECT_TRUE(error_has(ErrorAfterEdit([](nlohmann::json& j) {
                          j["camera"]["position"] = {0, 1e308, 0};
                        }),
                        "cornell-phosphor.json: camera.position[1]: expected a number in [-1e+06, 1e+06], got 1e+308"));
  EXPECT_TRUE(error_has(MediaErrorAfterEdit([](nlohmann::json& j) {
                          j["volumes"][0]["bounds"]["max"] = {1e308, 1, 1};
                        }),
                        "volumes[0].bounds.max[0]: expected a number in [-1e+06, 1e+06]"));
  EXPECT_TRUE(error_has(ErrorAfterEdit([](nlohmann::json& j) {
                          j["objects"][0]["transform"] = {{"scale", 1e300}};
                        }),
                        "objects[0].transform.scale: expected a number in [1e-06, 1e+06]"));
  EXPECT_TRUE(error_has(ErrorAfterEdit([](nlohmann::json& j) { j["time"]["end_s"] = 1e300; }), "time.end_s"));
  EXPECT_TRUE(error_has(ErrorAfterEdit([](nlohmann::json& j) { j["lights"][0]["intensity"] = 1e300; }),
                        "lights[0].intensity: expected a number in [0, 1e+09]"));
  EXPECT_TRUE(error_has(ErrorAfterEdit([](nlohmann::json& j) {
                          j["camera"]["width"] = 16384;
                          j["camera"]["height"] = 16384;
                        }),
                        "camera: 16384 x 16384 pixels is more than the limit of 67108864 pixels per frame"));
  // A volume scaled 100x hung: voxels over all volumes, and voxels x puffs, are capped.
  EXPECT_TRUE(
      error_has(MediaErrorAfterEdit([](nlohmann::json& j) {
                  j["volumes"][0]["resolution"] = {4096, 4096, 2};
                }),
                "volumes[0].resolution: the scene's volumes have 33554432 voxels, more than the limit of 16777216"));
  EXPECT_TRUE(error_has(MediaErrorAfterEdit([](nlohmann::json& j) { j["volumes"][0]["density"]["puffs"] = 100000; }),
                        "volumes[0].density.puffs: 100000 puffs over 43008 voxels is more than the limit of 1e+08"));
  // Huge bounds with a phosphor: "check failed: c.n_exc == 0 || E != nullptr".
  EXPECT_TRUE(error_has(MediaErrorAfterEdit([](nlohmann::json& j) {
                          j["volumes"][0]["bounds"]["min"] = {-1e30, 0, 0};
                        }),
                        "volumes[0].bounds.min[0]"));
}

// A phosphorescent volume of density 0 aborted with "check failed"
// in model/src/batch.cpp. An empty glowing medium has no voxels to glow and
// renders as empty space.
TEST(Scenes, AnEmptyGlowingMediumRenders) {
  nlohmann::json json = ReadJsonFile(Fixture("scenes/dust-sheets.json"));
  json["volumes"][0]["density"] = 0;
  const Scene scene = SceneFromJson(json, Fixture("scenes"), "dust-sheets.json");
  SceneGeometry geometry(scene);
  CoupledSolver solver(scene, geometry);
  ASSERT_NE(solver.media(), nullptr);
  solver.AdvanceTo(2.0);  // under the sweeping sheet: aborted here
  EXPECT_EQ(solver.media()->stats().phosphor_voxels, 0u);
  EXPECT_EQ(solver.media()->stats().voxels, 48u * 28 * 32);
}

// The glTF fixture, as JSON, to craft broken ones from.
nlohmann::json Pedestal() { return ReadJsonFile(Fixture("scenes/meshes/pedestal.gltf")); }

std::string GltfError(const nlohmann::json& gltf) {
  const std::string text = gltf.dump();
  return ErrorOfType<UserError>(
      [&] { ParseMesh(text, ".gltf", Fixture("scenes/meshes"), "crafted.gltf", "", "scene.json: objects[0].mesh"); });
}

// Crafted glTF files gave an ASan error (an accessor count that
// wraps), ran out of memory (a node graph of 2^40 instances), ended in
// "internal error: vector::reserve" (a 2^62 count) or "internal error"
// (missing buffers). Each is now one line naming the field.
TEST(Meshes, CraftedGltfFilesAreRefusedInOneLine) {
  EXPECT_EQ(GltfError(Pedestal()), "(no error)");
  auto has = [](const std::string& error, const std::string& part) {
    EXPECT_EQ(error.find('\n'), std::string::npos) << error;
    EXPECT_EQ(error.rfind("scene.json: objects[0].mesh", 0), 0u) << error;
    return error.find(part) != std::string::npos;
  };
  nlohmann::json j = Pedestal();
  j["accessors"][0]["count"] = std::uint64_t{1} << 62;
  EXPECT_TRUE(has(GltfError(j), "POSITION: accessor count 4611686018427387904 is more than the limit of 16777216"));
  j = Pedestal();
  j["accessors"][0]["count"] = 1000;  // within the limit, past the buffer (wrapped before)
  EXPECT_TRUE(has(GltfError(j), "POSITION: accessor reaches past the end of its buffer"));
  j = Pedestal();
  j["accessors"][0]["byteOffset"] = std::uint64_t{1} << 63;
  EXPECT_TRUE(has(GltfError(j), "POSITION: accessor"));
  j = Pedestal();
  j["bufferViews"][0]["buffer"] = 3;
  EXPECT_TRUE(has(GltfError(j), "cannot read glTF") || has(GltfError(j), "names a buffer that does not exist"));
  j = Pedestal();
  j.erase("buffers");
  EXPECT_TRUE(has(GltfError(j), "crafted.gltf"));
  j = Pedestal();
  j["scene"] = 5;
  EXPECT_TRUE(has(GltfError(j), "crafted.gltf"));
  // 41 nodes, each with its successor twice as children: 2^40 instances.
  j = Pedestal();
  j["scenes"][0]["nodes"] = {0};
  j["nodes"] = nlohmann::json::array();
  for (int i = 0; i < 40; ++i) j["nodes"].push_back({{"children", {i + 1, i + 1}}});
  j["nodes"].push_back({{"mesh", 0}});
  EXPECT_TRUE(has(GltfError(j), "nodes: the node graph has more than the limit of 65536 node instances"));
  // A node translation like 1e308 reached Embree's assertion.
  j = Pedestal();
  j["nodes"][0]["translation"] = {0, 1e308, 0};
  EXPECT_TRUE(has(GltfError(j), "crafted.gltf' has a vertex"));
  j = Pedestal();
  j["nodes"][0]["translation"] = {0, 2e6, 0};
  EXPECT_TRUE(has(GltfError(j), "has a vertex beyond the limit of 1e+06 m"));
  // tinygltf read a negative or fractional offset as 0, and an accessor past
  // its bufferView (within the buffer) read the next view's bytes: each
  // loaded in silence.
  j = Pedestal();
  j["bufferViews"][0]["byteOffset"] = -4;
  EXPECT_TRUE(has(GltfError(j), "(crafted.gltf): bufferViews[0].byteOffset: expected a whole number >= 0, got -4"));
  j = Pedestal();
  j["accessors"][1]["byteOffset"] = 0.5;
  EXPECT_TRUE(has(GltfError(j), "accessors[1].byteOffset: expected a whole number >= 0, got 0.5"));
  j = Pedestal();
  j["accessors"][0]["count"] = 9;  // 108 bytes of a 96-byte view, in a 168-byte buffer
  EXPECT_TRUE(has(GltfError(j), "POSITION: accessor reaches past the end of bufferView 0 (96 bytes)"));
  j = Pedestal();
  j["accessors"][0]["byteOffset"] = 12;
  EXPECT_TRUE(has(GltfError(j), "POSITION: accessor reaches past the end of bufferView 0 (96 bytes)"));
  j = Pedestal();
  j["accessors"][0]["count"] = 7;  // fewer than the view holds: read as given
  EXPECT_EQ(GltfError(j).find("bufferView"), std::string::npos);
}

// A 40 KB glTF whose extras held 20,000 nested arrays overflowed the stack in
// tinygltf's parse (a segfault of phos render, --check and the editor). The
// nesting is counted before tinygltf reads the JSON, of a .gltf and of a
// .glb's JSON chunk; a nesting within the limit reads as before.
TEST(Meshes, GltfJsonNestedPastTheLimitIsRefusedBeforeTinygltfReadsIt) {
  auto with_extras = [](int depth) {
    std::string text = Pedestal().dump();
    text.insert(1, "\"extras\":" + std::string(depth, '[') + std::string(depth, ']') + ",");
    return text;
  };
  auto glb = [](std::string json) {  // glTF 2.0, 4.4: header, then the JSON chunk padded with spaces
    while (json.size() % 4) json += ' ';
    auto u32 = [](std::uint32_t v) { return std::string(reinterpret_cast<const char*>(&v), 4); };
    return "glTF" + u32(2) + u32(static_cast<std::uint32_t>(20 + json.size())) +
           u32(static_cast<std::uint32_t>(json.size())) + "JSON" + json;
  };
  const std::string limit =
      "arrays and objects nested more than the limit of " + std::to_string(kMaxJsonNesting) + " levels deep";
  for (const std::string format : {".gltf", ".glb"}) {
    auto error = [&](int depth) {
      const std::string text = format == ".glb" ? glb(with_extras(depth)) : with_extras(depth);
      return ErrorOfType<UserError>([&] {
        ParseMesh(text, format, Fixture("scenes/meshes"), "deep" + format, "", "scene.json: objects[0].mesh");
      });
    };
    const std::string deep = error(20000);
    EXPECT_EQ(deep.rfind("scene.json: objects[0].mesh (deep" + format + "): " + limit, 0), 0u) << deep;
    EXPECT_EQ(deep.find('\n'), std::string::npos) << deep;
    EXPECT_EQ(error(kMaxJsonNesting - 1), "(no error)") << format;
  }
}

// tinyobjloader reads "nan", "inf", "1e999" or a word as 0 or infinity without
// a word: the vertex moved to the origin and the mesh rendered, exit 0.
TEST(Meshes, AnObjVertexThatIsNotAFiniteNumberIsRefused) {
  for (const std::string token : {"nan", "inf", "-inf", "1e999", "x"}) {
    const std::string obj = "v 0 0 0\nv 1 0 " + token + "\nv 0 1 0\nf 1 2 3\n";
    const std::string error =
        ErrorOfType<UserError>([&] { ParseMesh(obj, ".obj", ".", "crafted.obj", "", "s.json: objects[0].mesh"); });
    EXPECT_EQ(error, "s.json: objects[0].mesh: OBJ 'crafted.obj' line 2: vertex coordinate '" + token +
                         "' is not a finite number")
        << token;
  }
  EXPECT_NE(ErrorOfType<UserError>([&] {
              ParseMesh("v 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", ".obj", ".", "short.obj", "", "s.json");
            }).find("line 1: a vertex has fewer than 3 coordinates"),
            std::string::npos);
  // A fourth coordinate (w) and a carriage return are as before.
  EXPECT_NO_THROW(ParseMesh("v 0 0 0 1\r\nv 1 0 0\r\nv 0 1 0\r\nf 1 2 3\r\n", ".obj", ".", "w.obj", "", "s.json"));
}

// 92 mesh-loader rejections printed several lines (every rejection is one line).
TEST(Meshes, ObjRejectionsAreOneLine) {
  const std::string bad[] = {"v 0 0 0\nv 1 0 0\nf 1 2 7\n", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nv 1e39 0 0\n",
                             "f 1 2 3\nf 4 5 6\n", "v 1e7 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"};
  for (const std::string& obj : bad) {
    const std::string error =
        ErrorOfType<UserError>([&] { ParseMesh(obj, ".obj", ".", "crafted.obj", "", "s.json: objects[0].mesh"); });
    EXPECT_EQ(error.rfind("s.json: objects[0].mesh: ", 0), 0u) << error;
    EXPECT_EQ(error.find('\n'), std::string::npos) << error;
  }
  // tinyobjloader read an index of 99999999999999999999 as -1 (the last
  // vertex) and 4294967297 as 1: the face loaded in silence.
  const std::string triangle = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
  for (const std::string index : {"99999999999999999999", "-99999999999999999999", "4294967297", "2147483648", "1x"}) {
    const std::string error = ErrorOfType<UserError>(
        [&] { ParseMesh(triangle + "f 1 2/1 " + index + "\n", ".obj", ".", "crafted.obj", "", "s.json"); });
    EXPECT_EQ(error, "s.json: OBJ 'crafted.obj' line 4: face index '" + index +
                         "' is not a whole number within the vertex range")
        << index;
  }
  EXPECT_EQ(ParseMesh(triangle + "vt 0 0\nf 1/1 2/1 -1/1\n", ".obj", ".", "ok.obj", "", "s.json").triangles,
            std::vector<Eigen::Vector3i>({Eigen::Vector3i(0, 1, 2)}));
  // The mesh file itself: a regular file only.
  EXPECT_NE(ErrorOfType<UserError>([&] { LoadMesh("/dev/zero.obj", "", "s.json"); }).find("does not exist"),
            std::string::npos);
  testing::TempDir dir;
  ASSERT_EQ(::mkfifo((dir / "fifo.obj").c_str(), 0600), 0);
  EXPECT_NE(ErrorOfType<UserError>([&] { LoadMesh(dir / "fifo.obj", "", "s.json"); }).find("not a regular file"),
            std::string::npos);
}

}  // namespace
}  // namespace phos::render
