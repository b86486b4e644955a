#pragma once
// Small scenes built in code for the renderer's analytic tests.

#include <cmath>
#include <memory>
#include <vector>

#include "phos/model/material.h"
#include "phos/render/dss.h"
#include "phos/render/scene.h"

namespace phos::testing {

// nc = 1 on the paper's grid, every ke known (zero outside the given bands).
inline std::shared_ptr<Material> UniformPhosphor(double kr, std::vector<double> ke, std::vector<double> Lambda) {
  auto material = std::make_shared<Material>();
  material->name = "test phosphor";
  material->bands = SpectralGrid::Paper();
  ExcitedState state;
  state.kr = kr;
  for (double k : ke) state.ke.emplace_back(k);
  state.Lambda = std::move(Lambda);
  material->states.push_back(state);
  return material;
}

// A disk of radius R in the plane y = h, its front facing down (-y), as a fan of `sides` triangles.
inline render::Mesh DiskFacingDown(float R, float h, int sides = 96) {
  render::Mesh disk;
  disk.positions.push_back(Eigen::Vector3f(0, h, 0));
  for (int i = 0; i < sides; ++i) {
    const float angle = 2 * 3.14159265f * static_cast<float>(i) / static_cast<float>(sides);
    disk.positions.push_back(Eigen::Vector3f(R * std::cos(angle), h, R * std::sin(angle)));
  }
  for (int i = 0; i < sides; ++i) disk.triangles.push_back(Eigen::Vector3i(0, 1 + i, 1 + (i + 1) % sides));
  return disk;
}

inline render::Scene EmptyScene(int width = 16, int height = 16) {
  render::Scene scene;
  scene.source = "test scene";
  scene.name = "test";
  scene.bands = SpectralGrid::Paper();
  scene.camera.keys = {{0.0, render::Vec3(0, 0, 0), render::Vec3(0, 0, 1)}};
  scene.camera.width = width;
  scene.camera.height = height;
  scene.camera.fov_deg = 60;
  return scene;
}

inline render::Object MakeObject(const std::string& name, render::Mesh mesh, double albedo,
                                 std::shared_ptr<const Material> phosphor = nullptr) {
  render::Object object;
  object.name = name;
  object.mesh = std::make_shared<render::Mesh>(std::move(mesh));
  object.albedo.assign(8, albedo);
  object.phosphor = std::move(phosphor);
  object.phosphor_path = "in-memory material";
  return object;
}

// A point light with the given band irradiance at 1 m, optionally switched off at off_s.
inline render::Light PointLight(const render::Vec3& position, std::vector<double> E_per_band, double off_s = -1) {
  render::Light light;
  light.name = "test light";
  light.kind = render::Light::Kind::kPoint;
  light.position = position;
  light.E_per_band = std::move(E_per_band);
  if (off_s >= 0) light.schedule.keys = {{0.0, 1.0}, {off_s, 0.0}};
  return light;
}

// A floor 2 m wide at y = 0 (object 0) under a disk of radius R at height h
// facing down (object 1, DiskFacingDown), seen from
// 0.5 m above the floor looking straight down, 33 x 33 pixels: the centre
// pixel sees the floor on the disk's axis.
inline render::Scene DiskOverFloor(float R, float h) {
  render::Scene scene = EmptyScene(33, 33);
  scene.objects.push_back(MakeObject("floor", render::MakeQuad(2, 2), 0.5));
  scene.objects.push_back(MakeObject("disk", DiskFacingDown(R, h), 0.5));
  scene.camera.keys = {{0.0, render::Vec3(0, 0.5, 0), render::Vec3(0, 0, 0.0001)}};
  scene.camera.up = render::Vec3(0, 0, 1);
  return scene;
}

// The disk's surfels alone (s = 0.03) in a DiskOverFloor scene: what reaches
// points of the floor or of a medium on its axis (the floor's own surfels lie
// in the floor's plane).
inline std::vector<render::Surfel> DiskSurfels(const render::SceneGeometry& geometry,
                                               const render::CameraRays& camera) {
  render::SurfelOptions options;
  options.s = 0.03f;
  std::vector<render::Surfel> surfels;
  for (const render::Surfel& s : render::Surfelize(geometry, camera.origin(), 60, options))
    if (s.object == 1) surfels.push_back(s);
  return surfels;
}

}  // namespace phos::testing
