#pragma once
// The simulated lab the acquire tests run on: a Table 8.1 preset as the
// sample (reflectance 0.8), the default lights and camera, a virtual clock,
// and the rig changes a protocol asks for applied at once.

#include <string>
#include <vector>

#include "phos/acquire/protocols.h"
#include "phos/acquire/sim_lab.h"
#include "test_util.h"

namespace phos::testing {

struct Lab {
  VirtualClock clock;
  Material material;
  SimulatedLab lab;
  explicit Lab(const std::string& name, unsigned seed = 1)
      : material(LoadMaterial(Fixture("materials/" + name + ".json"))),
        lab(material, std::vector<double>(8, 0.8), DefaultLights(), Camera(seed), clock) {}
  static CameraModel Camera(unsigned seed) {
    CameraModel camera = DefaultCameraModel();
    camera.seed = seed;
    return camera;
  }
  RigChange Rig() {
    return [this](const std::string& what, bool in_place) {
      if (what == "lvf") lab.SetLvfInPath(in_place);
      if (what == "white_reference") lab.SetWhiteReferenceInView(in_place);
    };
  }
};

}  // namespace phos::testing
