#include "phos/render/surface_textures.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include <OpenImageIO/texture.h>
#include <unistd.h>
#include <xxhash.h>

#include "phos/util/atomic_file.h"
#include "phos/util/error.h"
#include "phos/util/format.h"

namespace phos::render {

std::vector<float> SampleMaskGrid(const std::filesystem::path& file, bool v_up, int resolution,
                                  const std::string& where) {
  // The process's shared TextureSystem, as SurfaceTextures (see there).
  OIIO::TextureSystem* system = OIIO::TextureSystem::create(/*shared=*/true);
  const OIIO::ustring name(file.string());
  system->invalidate(name);
  OIIO::TextureSystem::TextureHandle* handle = system->get_texture_handle(name);
  OIIO::ImageSpec spec;
  if (!handle || !system->get_imagespec(handle, nullptr, 0, spec)) {
    const std::string error = system->geterror();
    ThrowUserError(where, "phosphor_mask",
                   "mask file '" + file.string() + "' is not an image OpenImageIO can read" +
                       (error.empty() ? "" : ": " + error));
  }
  OIIO::TextureOpt options;
  options.swrap = options.twrap = OIIO::TextureOpt::WrapClamp;
  options.interpmode = OIIO::TextureOpt::InterpClosest;
  options.mipmode = OIIO::TextureOpt::MipModeNoMIP;
  std::vector<float> coverage(std::size_t(resolution) * resolution);
  OIIO::TextureSystem::Perthread* thread = system->get_perthread_info();
  for (int y = 0; y < resolution; ++y)
    for (int x = 0; x < resolution; ++x) {
      const float s = (static_cast<float>(x) + 0.5f) / static_cast<float>(resolution);
      const float v = (static_cast<float>(y) + 0.5f) / static_cast<float>(resolution);
      float value = 0;
      system->texture(handle, thread, options, s, v_up ? 1 - v : v, 0, 0, 0, 0, 1, &value);
      coverage[std::size_t(y) * resolution + x] = std::clamp(value, 0.0f, 1.0f);
    }
  return coverage;
}

namespace {

// The folder embedded images are written to: the user's cache
// ($XDG_CACHE_HOME/phos/textures, else ~/.cache/phos/textures), else the
// system's temporary folder (phos-textures-<uid>).
std::filesystem::path EmbeddedImageFolder() {
  const char* cache = std::getenv("XDG_CACHE_HOME");
  if (cache && cache[0] == '/') return std::filesystem::path(cache) / "phos" / "textures";
  const char* home = std::getenv("HOME");
  if (home && home[0] == '/') return std::filesystem::path(home) / ".cache" / "phos" / "textures";
  return std::filesystem::temp_directory_path() / ("phos-textures-" + std::to_string(::getuid()));
}

// The most the folder of embedded images keeps, in bytes:
// PHOS_TEXTURE_CACHE_MB (MiB, default 1024).
std::uintmax_t EmbeddedImageCacheBytes() {
  constexpr double kDefaultMiB = 1024;
  const char* text = std::getenv("PHOS_TEXTURE_CACHE_MB");
  double mib = kDefaultMiB;
  if (text && !ParseDouble(text, &mib)) mib = -1;
  if (!(mib >= 0) || mib > 1e9)
    ThrowUserError("", "PHOS_TEXTURE_CACHE_MB",
                   std::string("expected a size in MiB from 0 up, not '") + (text ? text : "") + "'");
  return static_cast<std::uintmax_t>(mib * 1024 * 1024);
}

// Keeps the folder of embedded images within `budget` bytes, as ccache
// keeps its cache: the files least recently used (their modification time,
// which a render that finds a file moves to now) go first. Files used in the
// last day stay whatever their size, as a render running beside this one
// may be reading them; so does `keep`, the file just written. A file that
// cannot be removed is left (another process's prune may have taken it).
void PruneEmbeddedImages(const std::filesystem::path& folder, std::uintmax_t budget,
                         const std::filesystem::path& keep) {
  struct File {
    std::filesystem::path path;
    std::filesystem::file_time_type used;
    std::uintmax_t bytes;
  };
  std::vector<File> files;
  std::uintmax_t total = 0;
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator(folder, ec)) {
    std::error_code entry_ec;
    if (!entry.is_regular_file(entry_ec)) continue;
    const std::uintmax_t bytes = entry.file_size(entry_ec);
    const std::filesystem::file_time_type used = entry.last_write_time(entry_ec);
    if (entry_ec) continue;
    files.push_back({entry.path(), used, bytes});
    total += bytes;
  }
  if (total <= budget) return;
  std::sort(files.begin(), files.end(), [](const File& a, const File& b) { return a.used < b.used; });
  const auto recent = std::filesystem::file_time_type::clock::now() - std::chrono::hours(24);
  for (const File& file : files) {
    if (total <= budget || file.used >= recent) break;
    if (file.path == keep) continue;
    if (std::filesystem::remove(file.path, ec)) total -= file.bytes;
  }
}

// The file OpenImageIO opens for a texture: its own, or for an image
// embedded in a glTF, a file holding its bytes in EmbeddedImageFolder(),
// named by a hash of them (XXH3, 128 bits) and written once: a second render,
// or two at once, find or write the same file. OpenImageIO 2.4's
// TextureSystem opens textures by name only; it takes no bytes from memory.
std::filesystem::path TextureFileOf(const TextureSource& source, const std::string& where) {
  if (!source.embedded) return source.texture;
  const EmbeddedImage& image = *source.embedded;
  const XXH128_hash_t hash = XXH3_128bits(image.bytes.data(), image.bytes.size());
  char name[40];
  std::snprintf(name, sizeof(name), "%016llx%016llx", static_cast<unsigned long long>(hash.high64),
                static_cast<unsigned long long>(hash.low64));
  const std::filesystem::path folder = EmbeddedImageFolder();
  const std::filesystem::path file = folder / (name + image.extension);
  const std::uintmax_t budget = EmbeddedImageCacheBytes();
  std::error_code ec;
  if (std::filesystem::is_regular_file(file, ec) && std::filesystem::file_size(file, ec) == image.bytes.size()) {
    // Used now: the prune below keeps the files used last.
    std::filesystem::last_write_time(file, std::filesystem::file_time_type::clock::now(), ec);
    return file;
  }
  std::filesystem::create_directories(folder, ec);
  if (ec)
    ThrowUserError(where, source.field,
                   "cannot create the folder '" + folder.string() + "' for its embedded image: " + ec.message());
  WriteFileAtomically(file, image.bytes);
  PruneEmbeddedImages(folder, budget, file);
  return file;
}

}  // namespace

SurfaceTextures::SurfaceTextures(const Scene& scene)
    : scene_(scene),
      to_bands_(scene.bands),
      handles_(scene.objects.size(), nullptr),
      gloss_handles_(scene.objects.size(), nullptr),
      srgb_(scene.objects.size(), 0) {
  // The process's shared TextureSystem, never destroyed: OpenImageIO 2.4's
  // TextureSystem::destroy of a private one deletes it through the wrong
  // type (AddressSanitizer: new-delete-type-mismatch). A file re-read by a
  // later geometry is invalidated below, so an edited texture is seen.
  system_ = OIIO::TextureSystem::create(/*shared=*/true);
  // PNG and JPEG files are neither tiled nor mip-mapped: the cache builds the
  // levels on first use, so a file from any exporter is filtered, not aliased.
  system_->attribute("automip", 1);
  system_->attribute("gray_to_rgb", 1);
  for (std::size_t o = 0; o < scene.objects.size(); ++o) {
    const Object& object = scene.objects[o];
    const std::string where =
        scene.source + ": objects[" + std::to_string(o) + "] '" + object.name + "': " + object.mesh->source;
    if (object.albedo_texture) {
      OIIO::ImageSpec spec;
      handles_[o] = Open(*object.albedo_texture, where, spec);
      // glTF says a base colour texture is sRGB-encoded; 8- and 16-bit images
      // are taken as such, float ones (EXR) as linear.
      srgb_[o] = !spec.format.is_floating_point();
    }
    if (object.gloss_texture) {
      OIIO::ImageSpec spec;
      gloss_handles_[o] = Open(*object.gloss_texture, where, spec);
    }
  }
}

void* SurfaceTextures::Open(const TextureSource& source, const std::string& where, OIIO::ImageSpec& spec) const {
  const OIIO::ustring file(TextureFileOf(source, where).string());
  system_->invalidate(file);
  OIIO::TextureSystem::TextureHandle* handle = system_->get_texture_handle(file);
  if (!handle || !system_->get_imagespec(handle, nullptr, 0, spec)) {
    // OpenImageIO's message may hold newlines: ThrowUserError escapes them (one line).
    const std::string error = system_->geterror();
    ThrowUserError(where, source.field,
                   "texture file '" + source.texture.string() + "' is not an image OpenImageIO can read" +
                       (error.empty() ? "" : ": " + error));
  }
  return handle;
}

SurfaceTextures::~SurfaceTextures() = default;

namespace {

// The UV offsets of the points hit + dp_dx and hit + dp_dy of the hit's
// plane (the footprint), through their barycentric offsets in the hit's
// world-space triangle: one solve of its 2 x 2 normal equations for both.
void UvOffsets(const SceneGeometry& geometry, const Hit& hit, const Mesh& mesh, const Vec3f& dp_dx,
               const Vec3f& dp_dy, Eigen::Vector2f& duv_dx, Eigen::Vector2f& duv_dy) {
  const Vec3f v0 = geometry.Vertex(hit.object, hit.triangle, 0);
  const Vec3f e1 = geometry.Vertex(hit.object, hit.triangle, 1) - v0;
  const Vec3f e2 = geometry.Vertex(hit.object, hit.triangle, 2) - v0;
  const float d11 = e1.dot(e1), d12 = e1.dot(e2), d22 = e2.dot(e2);
  const float det = d11 * d22 - d12 * d12;
  if (!(det > 0)) {  // a degenerate triangle: a point lookup
    duv_dx.setZero();
    duv_dy.setZero();
    return;
  }
  const Eigen::Vector3i& t = mesh.uv_triangles[hit.triangle];
  const Eigen::Vector2f uv1 = mesh.uvs[t[1]] - mesh.uvs[t[0]], uv2 = mesh.uvs[t[2]] - mesh.uvs[t[0]];
  auto offset = [&](const Vec3f& dp) -> Eigen::Vector2f {
    const float p1 = dp.dot(e1), p2 = dp.dot(e2);
    return (d22 * p1 - d12 * p2) / det * uv1 + (d11 * p2 - d12 * p1) / det * uv2;
  };
  duv_dx = offset(dp_dx);
  duv_dy = offset(dp_dy);
}

}  // namespace

namespace {

OIIO::TextureOpt::Wrap OiioWrap(TextureWrap wrap) {
  switch (wrap) {
    case TextureWrap::kClampToEdge: return OIIO::TextureOpt::WrapClamp;
    case TextureWrap::kMirroredRepeat: return OIIO::TextureOpt::WrapMirror;
    case TextureWrap::kRepeat: break;
  }
  return OIIO::TextureOpt::WrapPeriodic;
}

OIIO::TextureOpt::InterpMode OiioInterpolation(TexelInterpolation interpolation) {
  return interpolation == TexelInterpolation::kClosest ? OIIO::TextureOpt::InterpClosest
                                                       : OIIO::TextureOpt::InterpBilinear;
}

OIIO::TextureOpt::MipMode OiioMipMode(MipLevels mip) {
  switch (mip) {
    case MipLevels::kNone: return OIIO::TextureOpt::MipModeNoMIP;
    case MipLevels::kNearestLevel: return OIIO::TextureOpt::MipModeOneLevel;
    case MipLevels::kTrilinear: break;
  }
  return OIIO::TextureOpt::MipModeTrilinear;
}

}  // namespace

UvFootprint SurfaceTextures::Footprint(const SceneGeometry& geometry, const Hit& hit, const Vec3f& dp_dx,
                                       const Vec3f& dp_dy) const {
  const Mesh& mesh = *scene_.objects[hit.object].mesh;
  const Eigen::Vector3i& t = mesh.uv_triangles[hit.triangle];
  UvFootprint footprint;
  footprint.uv = (1 - hit.b1 - hit.b2) * mesh.uvs[t[0]] + hit.b1 * mesh.uvs[t[1]] + hit.b2 * mesh.uvs[t[2]];
  if (!dp_dx.isZero() || !dp_dy.isZero())
    UvOffsets(geometry, hit, mesh, dp_dx, dp_dy, footprint.duv_dx, footprint.duv_dy);
  return footprint;
}

void SurfaceTextures::Lookup(void* handle, const UvFootprint& footprint, bool v_up, const TextureSource& source,
                             int first_channel, int channels, float* out) const {
  // OpenImageIO's t runs down the image from its top row, as glTF's v; an
  // OBJ's v runs up from the bottom row.
  const float flip = v_up ? -1.0f : 1.0f;
  // The texture's own UV (KHR_texture_transform): the point through the
  // whole affine map, the footprint's offsets through its linear part.
  const UvTransform& transform = source.uv_transform;
  const Eigen::Vector2f uv = transform(footprint.uv), duv_dx = transform.linear * footprint.duv_dx,
                        duv_dy = transform.linear * footprint.duv_dy;
  OIIO::TextureOpt options;
  options.swrap = OiioWrap(source.wraps.s);
  options.twrap = OiioWrap(source.wraps.t);
  // Unless the sampler says otherwise, trilinear across levels, bilinear
  // within one: OpenImageIO's defaults (smart bicubic, anisotropic) took
  // 2.9x the untextured frame and bilinear-anisotropic 2.4x, trilinear 1.9x
  // (bench_render, BM_TexturedDirectFrame); docs/render.md says what it blurs.
  options.interpmode = OiioInterpolation(source.filter.interpolation);
  options.mipmode = OiioMipMode(source.filter.mip);
  options.firstchannel = first_channel;
  system_->texture(static_cast<OIIO::TextureSystem::TextureHandle*>(handle), system_->get_perthread_info(), options,
                   uv.x(), v_up ? 1 - uv.y() : uv.y(), duv_dx.x(), flip * duv_dx.y(), duv_dy.x(), flip * duv_dy.y(),
                   channels, out);
}

void SurfaceTextures::Albedo(int object, const UvFootprint& footprint, float* bands) const {
  const BaseColour& colour = *scene_.objects[object].albedo_texture;
  float rgb[3] = {0, 0, 0};
  Lookup(handles_[object], footprint, colour.v_up, colour, 0, 3, rgb);
  for (int c = 0; c < 3; ++c) {
    // Decoded after the filter: OpenImageIO 2.4's TextureSystem has no
    // colour transform (docs/render.md, "Textures", says what that costs).
    const float linear = srgb_[object] ? SrgbToLinear(rgb[c]) : rgb[c];
    rgb[c] = colour.factor[c] * linear;
  }
  to_bands_.Albedo(rgb, bands);
}

Gloss SurfaceTextures::GlossAt(int object, const UvFootprint& footprint, const Gloss& factors) const {
  float roughness_metallic[2] = {1, 1};  // glTF: G roughness, B metallic
  const Object& o = scene_.objects[object];
  Lookup(gloss_handles_[object], footprint, o.mesh->v_up, *o.gloss_texture, 1, 2, roughness_metallic);
  return {factors.metallic * std::clamp(roughness_metallic[1], 0.0f, 1.0f),
          factors.roughness * std::clamp(roughness_metallic[0], 0.0f, 1.0f)};
}

}  // namespace phos::render
