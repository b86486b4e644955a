#include "phos/acquire/aravis_camera.h"

#include <arv.h>

#include <algorithm>
#include <cstring>

#include "phos/util/error.h"
#include "phos/util/format.h"

namespace phos {

struct AravisCamera::Impl {
  ArvCamera* camera = nullptr;
  ArvStream* stream = nullptr;
  std::string id;
};

namespace {

// Turns a GError into the one way phos reports a problem, naming the camera.
void Check(GError* error, const std::string& camera, const std::string& what) {
  if (error == nullptr) return;
  std::string message = error->message;
  g_error_free(error);
  ThrowUserError("camera '" + camera + "'", what, message);
}

}  // namespace

void AravisCamera::EnableFakeInterface() { arv_enable_interface("Fake"); }

AravisCamera::AravisCamera(const std::string& device_id, const Clock& clock, double timeout_s)
    : impl_(std::make_unique<Impl>()), clock_(clock), timeout_s_(timeout_s) {
  impl_->id = device_id;
  GError* error = nullptr;
  impl_->camera = arv_camera_new(device_id.c_str(), &error);
  Check(error, device_id, "open");
  if (impl_->camera == nullptr) ThrowUserError("camera '" + device_id + "'", "open", "not found");
  // Frames as raw as the camera gives them: the deepest mono format it has.
  const std::vector<std::string> formats = available_pixel_formats();
  for (const char* preferred : {"Mono16", "Mono12", "Mono10", "Mono8"})
    if (std::find(formats.begin(), formats.end(), preferred) != formats.end()) {
      arv_camera_set_pixel_format_from_string(impl_->camera, preferred, &error);
      Check(error, device_id, "pixel format");
      break;
    }
  // GigE Vision: plain UDP sockets, with a fixed receive buffer. The packet
  // socket needs CAP_NET_RAW and, as root on loopback, receives nothing.
  if (arv_camera_is_gv_device(impl_->camera))
    arv_camera_gv_set_stream_options(impl_->camera, ARV_GV_STREAM_OPTION_PACKET_SOCKET_DISABLED);
  if (arv_camera_is_feature_available(impl_->camera, "AcquisitionMode", nullptr))
    arv_camera_set_acquisition_mode(impl_->camera, ARV_ACQUISITION_MODE_SINGLE_FRAME, nullptr);
  AllocateBuffers();
}

void AravisCamera::AllocateBuffers() {
  // A new stream with two buffers of the current payload: the old stream's
  // queued buffers have the old size (a region or binning change), and a
  // stream gives back only the buffers it has filled.
  GError* error = nullptr;
  if (impl_->stream) g_object_unref(impl_->stream);
  impl_->stream = arv_camera_create_stream(impl_->camera, nullptr, nullptr, &error);
  Check(error, impl_->id, "stream");
  if (ARV_IS_GV_STREAM(impl_->stream))
    g_object_set(impl_->stream, "socket-buffer", ARV_GV_STREAM_SOCKET_BUFFER_FIXED, "socket-buffer-size",
                 8 * 1024 * 1024, nullptr);
  const guint payload = arv_camera_get_payload(impl_->camera, &error);
  Check(error, impl_->id, "payload");
  for (int i = 0; i < 2; ++i) arv_stream_push_buffer(impl_->stream, arv_buffer_new_allocate(payload));
}

std::vector<std::string> AravisCamera::available_pixel_formats() const {
  GError* error = nullptr;
  guint n = 0;
  const char** names = arv_camera_dup_available_pixel_formats_as_strings(impl_->camera, &n, &error);
  Check(error, impl_->id, "pixel formats");
  std::vector<std::string> result;
  for (guint i = 0; i < n; ++i)
    if (names[i] != nullptr) result.emplace_back(names[i]);
  g_free(names);
  return result;
}

void AravisCamera::SetPixelFormat(const std::string& name) {
  const std::vector<std::string> formats = available_pixel_formats();
  if (std::find(formats.begin(), formats.end(), name) == formats.end()) {
    std::string known;
    for (const std::string& f : formats) known += (known.empty() ? "" : ", ") + f;
    ThrowUserError("camera '" + impl_->id + "'", "pixel format", "does not offer '" + name + "' (it has: " + known + ")");
  }
  GError* error = nullptr;
  arv_camera_set_pixel_format_from_string(impl_->camera, name.c_str(), &error);
  Check(error, impl_->id, "pixel format");
  AllocateBuffers();
}

std::string AravisCamera::pixel_format() const {
  GError* error = nullptr;
  const char* name = arv_camera_get_pixel_format_as_string(impl_->camera, &error);
  Check(error, impl_->id, "pixel format");
  return name ? name : "";
}

void AravisCamera::SetBinning(int dx, int dy) {
  GError* error = nullptr;
  if (!arv_camera_is_binning_available(impl_->camera, nullptr))
    ThrowUserError("camera '" + impl_->id + "'", "binning", "the camera has no binning");
  gint lo = 0, hi = 0;
  arv_camera_get_x_binning_bounds(impl_->camera, &lo, &hi, &error);
  Check(error, impl_->id, "binning");
  if (dx < lo || dx > hi || dy < lo || dy > hi)
    ThrowUserError("camera '" + impl_->id + "'", "binning",
                   "refuses " + std::to_string(dx) + "x" + std::to_string(dy) + " (it takes " + std::to_string(lo) +
                       " to " + std::to_string(hi) + ")");
  arv_camera_set_binning(impl_->camera, dx, dy, &error);
  Check(error, impl_->id, "binning");
  // The region is in binned pixels: keep it inside the binned sensor (some
  // cameras clamp it themselves, others, like Aravis's fake, do not).
  gint x = 0, y = 0, width = 0, height = 0, wmin = 0, wmax = 0, hmin = 0, hmax = 0;
  arv_camera_get_region(impl_->camera, &x, &y, &width, &height, &error);
  Check(error, impl_->id, "region");
  arv_camera_get_width_bounds(impl_->camera, &wmin, &wmax, &error);
  Check(error, impl_->id, "region");
  arv_camera_get_height_bounds(impl_->camera, &hmin, &hmax, &error);
  Check(error, impl_->id, "region");
  gint sensor_width = 0, sensor_height = 0;
  arv_camera_get_sensor_size(impl_->camera, &sensor_width, &sensor_height, nullptr);
  if (sensor_width > 0) wmax = std::min(wmax, sensor_width / dx);
  if (sensor_height > 0) hmax = std::min(hmax, sensor_height / dy);
  if (x + width > wmax || y + height > hmax) {
    x = std::min(x, wmax - 1);
    y = std::min(y, hmax - 1);
    arv_camera_set_region(impl_->camera, x, y, std::min(width, wmax - x), std::min(height, hmax - y), &error);
    Check(error, impl_->id, "region");
  }
  AllocateBuffers();
}

std::pair<int, int> AravisCamera::binning() const {
  GError* error = nullptr;
  gint dx = 1, dy = 1;
  arv_camera_get_binning(impl_->camera, &dx, &dy, &error);
  Check(error, impl_->id, "binning");
  return {dx, dy};
}

std::pair<int, int> AravisCamera::sensor_size() const {
  GError* error = nullptr;
  gint width = 0, height = 0;
  arv_camera_get_sensor_size(impl_->camera, &width, &height, &error);
  Check(error, impl_->id, "sensor size");
  return {width, height};
}

std::vector<std::string> AravisCamera::available_trigger_sources() const {
  GError* error = nullptr;
  guint n = 0;
  const char** names = arv_camera_dup_available_trigger_sources(impl_->camera, &n, &error);
  Check(error, impl_->id, "trigger sources");
  std::vector<std::string> result;
  for (guint i = 0; i < n; ++i)
    if (names[i] != nullptr) result.emplace_back(names[i]);
  g_free(names);
  return result;
}

void AravisCamera::SetTrigger(Trigger trigger, const std::string& source) {
  GError* error = nullptr;
  if (trigger == Trigger::kFreeRun) {
    arv_camera_clear_triggers(impl_->camera, &error);
    Check(error, impl_->id, "trigger");
    if (arv_camera_is_feature_available(impl_->camera, "AcquisitionMode", nullptr))
      arv_camera_set_acquisition_mode(impl_->camera, ARV_ACQUISITION_MODE_SINGLE_FRAME, nullptr);
  } else {
    const std::string wanted = trigger == Trigger::kSoftware ? "Software" : source;
    if (trigger == Trigger::kSoftware && !arv_camera_is_software_trigger_supported(impl_->camera, nullptr))
      ThrowUserError("camera '" + impl_->id + "'", "trigger", "the camera has no software trigger");
    const std::vector<std::string> sources = available_trigger_sources();
    if (std::find(sources.begin(), sources.end(), wanted) == sources.end()) {
      std::string known;
      for (const std::string& f : sources) known += (known.empty() ? "" : ", ") + f;
      ThrowUserError("camera '" + impl_->id + "'", "trigger", "has no trigger source '" + wanted + "' (it has: " + known + ")");
    }
    // FrameStart on the rising edge of `wanted`, acquisition continuous (armed).
    arv_camera_set_trigger(impl_->camera, wanted.c_str(), &error);
    Check(error, impl_->id, "trigger");
  }
  trigger_ = trigger;
  trigger_source_ = source;
}

void AravisCamera::SetRegion(int x, int y, int width, int height) {
  GError* error = nullptr;
  arv_camera_set_region(impl_->camera, x, y, width, height, &error);
  Check(error, impl_->id, "region");
  AllocateBuffers();
}

AravisCamera::~AravisCamera() {
  if (!impl_) return;
  if (impl_->stream) g_object_unref(impl_->stream);
  if (impl_->camera) g_object_unref(impl_->camera);
}

std::string AravisCamera::description() const {
  GError* error = nullptr;
  const char* vendor = arv_camera_get_vendor_name(impl_->camera, &error);
  if (error) g_clear_error(&error);
  const char* model = arv_camera_get_model_name(impl_->camera, &error);
  if (error) g_clear_error(&error);
  return std::string("Aravis camera '") + impl_->id + "' (" + (vendor ? vendor : "?") + " " + (model ? model : "?") + ")";
}

double AravisCamera::max_exposure_s() const {
  GError* error = nullptr;
  double lo = 0, hi = 0;
  arv_camera_get_exposure_time_bounds(impl_->camera, &lo, &hi, &error);
  Check(error, impl_->id, "exposure bounds");
  return hi * 1e-6;
}

double AravisCamera::exposure_s() const {
  GError* error = nullptr;
  const double us = arv_camera_get_exposure_time(impl_->camera, &error);
  Check(error, impl_->id, "exposure");
  return us * 1e-6;
}

double AravisCamera::gain() const {
  GError* error = nullptr;
  const double g = arv_camera_get_gain(impl_->camera, &error);
  Check(error, impl_->id, "gain");
  return g;
}

Frame AravisCamera::Capture(double exposure_s, double gain) {
  GError* error = nullptr;
  double lo = 0, hi = 0;
  arv_camera_get_exposure_time_bounds(impl_->camera, &lo, &hi, &error);
  Check(error, impl_->id, "exposure bounds");
  const double us = exposure_s * 1e6;
  if (!(us >= lo && us <= hi))
    ThrowUserError("camera '" + impl_->id + "'", "exposure",
                   "refuses " + FormatDouble(exposure_s) + " s (it takes " + FormatShort(lo * 1e-6) + " to " +
                       FormatShort(hi * 1e-6) + " s)");
  arv_camera_set_exposure_time(impl_->camera, us, &error);
  Check(error, impl_->id, "exposure");
  arv_camera_get_gain_bounds(impl_->camera, &lo, &hi, &error);
  Check(error, impl_->id, "gain bounds");
  if (!(gain >= lo && gain <= hi))
    ThrowUserError("camera '" + impl_->id + "'", "gain",
                   "refuses " + FormatDouble(gain) + " (it takes " + FormatShort(lo) + " to " + FormatShort(hi) + ")");
  arv_camera_set_gain(impl_->camera, gain, &error);
  Check(error, impl_->id, "gain");

  Frame frame;
  frame.t_start_s = clock_.now_s();
  frame.exposure_s = arv_camera_get_exposure_time(impl_->camera, &error) * 1e-6;  // what the camera set
  Check(error, impl_->id, "exposure");
  frame.gain = arv_camera_get_gain(impl_->camera, &error);
  Check(error, impl_->id, "gain");
  if (arv_camera_is_black_level_available(impl_->camera, nullptr))
    frame.black_level_dn = arv_camera_get_black_level(impl_->camera, nullptr);

  // A frame left from an earlier acquisition was exposed with other settings.
  while (ArvBuffer* stale = arv_stream_try_pop_buffer(impl_->stream)) arv_stream_push_buffer(impl_->stream, stale);
  ArvBuffer* buffer = nullptr;
  for (int attempt = 1;; ++attempt) {
    frame.t_start_s = clock_.now_s();
    arv_camera_start_acquisition(impl_->camera, &error);
    Check(error, impl_->id, "acquisition");
    if (trigger_ == Trigger::kSoftware) {
      frame.t_start_s = clock_.now_s();
      arv_camera_software_trigger(impl_->camera, &error);
      if (error != nullptr) arv_camera_stop_acquisition(impl_->camera, nullptr);
      Check(error, impl_->id, "software trigger");
    } else if (trigger_ == Trigger::kHardware && fire_hardware_trigger) {
      frame.t_start_s = clock_.now_s();
      fire_hardware_trigger();
    }
    buffer = arv_stream_timeout_pop_buffer(impl_->stream, static_cast<guint64>((exposure_s + timeout_s_) * 1e6));
    arv_camera_stop_acquisition(impl_->camera, nullptr);
    if (buffer == nullptr && trigger_ == Trigger::kHardware)
      ThrowUserError("camera '" + impl_->id + "'", "acquisition",
                     "no frame within " + FormatShort(exposure_s + timeout_s_) + " s: the hardware trigger on '" +
                         trigger_source_ + "' did not fire (check its wiring)");
    if (buffer == nullptr)
      ThrowUserError("camera '" + impl_->id + "'", "acquisition", "no frame arrived in time (disconnected?)");
    if (arv_buffer_get_status(buffer) == ARV_BUFFER_STATUS_SUCCESS) break;
    const int status = arv_buffer_get_status(buffer);
    arv_stream_push_buffer(impl_->stream, buffer);
    if (attempt == 3)
      ThrowUserError("camera '" + impl_->id + "'", "acquisition",
                     "3 frames in a row arrived incomplete (status " + std::to_string(status) + "): check the link");
  }
  // The buffer goes back to the stream on every way out.
  struct Requeue {
    ArvStream* stream;
    ArvBuffer* buffer;
    ~Requeue() { arv_stream_push_buffer(stream, buffer); }
  } requeue{impl_->stream, buffer};
  gint x = 0, y = 0, width = 0, height = 0;
  arv_buffer_get_image_region(buffer, &x, &y, &width, &height);
  const ArvPixelFormat format = arv_buffer_get_image_pixel_format(buffer);
  size_t size = 0;
  const auto* data = static_cast<const unsigned char*>(arv_buffer_get_image_data(buffer, &size));
  frame.width = width;
  frame.height = height;
  frame.channels = 1;
  frame.pixels.resize(static_cast<std::size_t>(width) * height);
  // Unpacked formats only: 8 bits per pixel, or 10-16 significant bits in 16.
  const int container_bits = ARV_PIXEL_FORMAT_BIT_PER_PIXEL(format);
  const char* name_now = arv_camera_get_pixel_format_as_string(impl_->camera, nullptr);
  const std::string format_name = name_now ? name_now : "";
  const bool bayer = format_name.rfind("Bayer", 0) == 0;
  if (format_name.find("Packed") != std::string::npos || (!format_name.empty() && format_name.back() == 'p') ||
      (container_bits != 8 && container_bits != 16))
    ThrowUserError("camera '" + impl_->id + "'", "pixel format",
                   "'" + format_name + "' is packed or not 8/16-bit (use Mono8-16 or unpacked Bayer)");
  if (container_bits == 16 && size >= frame.pixels.size() * 2) {
    std::memcpy(frame.pixels.data(), data, frame.pixels.size() * 2);
  } else if (container_bits == 8 && size >= frame.pixels.size()) {
    std::copy(data, data + frame.pixels.size(), frame.pixels.begin());
  } else {
    ThrowUserError("camera '" + impl_->id + "'", "acquisition", "frame smaller than its region (" + format_name + ")");
  }
  // Significant bits: the number in the format's name (Mono12 -> 12).
  const std::size_t digits = format_name.find_first_of("0123456789");
  frame.adc_bits = digits == std::string::npos ? container_bits : std::atoi(format_name.c_str() + digits);
  if (frame.adc_bits < 1 || frame.adc_bits > 16) frame.adc_bits = container_bits;
  frame.channel_names = {bayer ? format_name.substr(0, format_name.find_first_of("0123456789")) : std::string("Y")};
  frame.camera_timestamp_ns = arv_buffer_get_timestamp(buffer);
  if (arv_camera_is_feature_available(impl_->camera, "DeviceTemperature", nullptr))
    frame.sensor_temperature_c = arv_camera_get_float(impl_->camera, "DeviceTemperature", nullptr);
  last_frame_id_ = arv_buffer_get_frame_id(buffer);
  last_camera_timestamp_ns_ = arv_buffer_get_timestamp(buffer);
  return frame;
}

}  // namespace phos
