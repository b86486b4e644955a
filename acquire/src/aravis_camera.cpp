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
  AravisCamera::StreamStatistics carried;  // of the streams retakes replaced
};

namespace {

// Turns a GError into the one way phos reports a problem, naming the camera.
void Check(GError* error, const std::string& camera, const std::string& what) {
  if (error == nullptr) return;
  std::string message = error->message;
  g_error_free(error);
  ThrowUserError("camera '" + camera + "'", what, message);
}

// One of the stream's counters by name, or 0 where the stream keeps none
// (only GigE Vision streams count packets; asking Aravis for a counter a
// stream did not declare prints a critical warning).
std::uint64_t StreamCount(ArvStream* stream, const char* name) {
  if (stream == nullptr || !ARV_IS_GV_STREAM(stream)) return 0;
  const guint n = arv_stream_get_n_infos(stream);
  for (guint i = 0; i < n; ++i) {
    const char* info = arv_stream_get_info_name(stream, i);
    if (info != nullptr && std::strcmp(info, name) == 0 && arv_stream_get_info_type(stream, i) == G_TYPE_UINT64)
      return arv_stream_get_info_uint64(stream, i);
  }
  return 0;
}

// The largest width and height of a region at the camera's binning: its
// WidthMax and HeightMax, and at most the sensor over the binning (Aravis's
// fake reports the unbinned WidthMax).
std::pair<int, int> BinnedSensorSize(ArvCamera* camera, const std::string& id) {
  GError* error = nullptr;
  gint wmin = 0, wmax = 0, hmin = 0, hmax = 0, dx = 1, dy = 1;
  arv_camera_get_width_bounds(camera, &wmin, &wmax, &error);
  Check(error, id, "region");
  arv_camera_get_height_bounds(camera, &hmin, &hmax, &error);
  Check(error, id, "region");
  gint sensor_width = 0, sensor_height = 0;
  arv_camera_get_sensor_size(camera, &sensor_width, &sensor_height, nullptr);
  if (arv_camera_is_binning_available(camera, nullptr)) arv_camera_get_binning(camera, &dx, &dy, nullptr);
  if (sensor_width > 0 && dx > 0) wmax = std::min(wmax, sensor_width / dx);
  if (sensor_height > 0 && dy > 0) hmax = std::min(hmax, sensor_height / dy);
  return {wmax, hmax};
}

// Why a buffer is not a whole frame, or "" when it is: its status, or fewer
// bytes than its region needs (a trailer that came early).
std::string WhyIncomplete(ArvBuffer* buffer) {
  switch (arv_buffer_get_status(buffer)) {
    case ARV_BUFFER_STATUS_SUCCESS: break;
    case ARV_BUFFER_STATUS_TIMEOUT: return "timeout: packets lost and not resent in time";
    case ARV_BUFFER_STATUS_MISSING_PACKETS: return "packets missing";
    case ARV_BUFFER_STATUS_WRONG_PACKET_ID: return "a packet out of place";
    case ARV_BUFFER_STATUS_SIZE_MISMATCH: return "larger than its buffer";
    case ARV_BUFFER_STATUS_ABORTED: return "aborted";
    case ARV_BUFFER_STATUS_CLEARED:
    case ARV_BUFFER_STATUS_FILLING: return "never filled";
    default: return "status " + std::to_string(static_cast<int>(arv_buffer_get_status(buffer)));
  }
  gint x = 0, y = 0, width = 0, height = 0;
  arv_buffer_get_image_region(buffer, &x, &y, &width, &height);
  const int container_bits = ARV_PIXEL_FORMAT_BIT_PER_PIXEL(arv_buffer_get_image_pixel_format(buffer));
  if (container_bits != 8 && container_bits != 16) return "";  // refused as a format, not as the link's fault
  size_t size = 0;
  arv_buffer_get_image_data(buffer, &size);
  const std::size_t needed = static_cast<std::size_t>(width) * height * (container_bits / 8);
  if (size < needed) return std::to_string(size) + " of its " + std::to_string(needed) + " bytes";
  return "";
}

// Sets the exposure and the gain, each refused (naming the camera's range)
// when the camera does not take it.
void SetExposureAndGain(ArvCamera* camera, const std::string& id, double exposure_s, double gain) {
  GError* error = nullptr;
  double lo = 0, hi = 0;
  arv_camera_get_exposure_time_bounds(camera, &lo, &hi, &error);
  Check(error, id, "exposure bounds");
  const double us = exposure_s * 1e6;
  if (!(us >= lo && us <= hi))
    ThrowUserError("camera '" + id + "'", "exposure",
                   "refuses " + FormatDouble(exposure_s) + " s (it takes " + FormatShort(lo * 1e-6) + " to " +
                       FormatShort(hi * 1e-6) + " s)");
  arv_camera_set_exposure_time(camera, us, &error);
  Check(error, id, "exposure");
  arv_camera_get_gain_bounds(camera, &lo, &hi, &error);
  Check(error, id, "gain bounds");
  if (!(gain >= lo && gain <= hi))
    ThrowUserError("camera '" + id + "'", "gain",
                   "refuses " + FormatDouble(gain) + " (it takes " + FormatShort(lo) + " to " + FormatShort(hi) + ")");
  arv_camera_set_gain(camera, gain, &error);
  Check(error, id, "gain");
}

// The frame of the try that began at try_started_ns, or null when none came
// within try_timeout_us.
ArvBuffer* PopThisFrame(ArvStream* stream, gint64 try_timeout_us, gint64 try_started_ns) {
  const gint64 deadline_us = g_get_monotonic_time() + try_timeout_us;
  for (gint64 left_us = try_timeout_us; left_us > 0; left_us = deadline_us - g_get_monotonic_time()) {
    ArvBuffer* popped = arv_stream_timeout_pop_buffer(stream, static_cast<guint64>(left_us));
    if (popped == nullptr) return nullptr;
    // A whole frame whose first packet reached the host before this try
    // began was exposed before it (one that came in behind a frame held
    // back while its lost packets were awaited, or one from earlier
    // settings): it is dropped, so t_start_s and the settings are the
    // frame's own. An incomplete one is retaken whatever its age.
    if (arv_buffer_get_status(popped) != ARV_BUFFER_STATUS_SUCCESS ||
        arv_buffer_get_system_timestamp(popped) >= static_cast<guint64>(try_started_ns))
      return popped;
    arv_stream_push_buffer(stream, popped);
  }
  return nullptr;
}

// A whole frame's pixels, region, bit depth, channel, timestamp and sensor
// temperature into `frame`.
void ReadFrame(ArvCamera* camera, const std::string& id, ArvBuffer* buffer, Frame& frame) {
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
  const char* name_now = arv_camera_get_pixel_format_as_string(camera, nullptr);
  const std::string format_name = name_now ? name_now : "";
  const bool bayer = format_name.rfind("Bayer", 0) == 0;
  if (format_name.find("Packed") != std::string::npos || (!format_name.empty() && format_name.back() == 'p') ||
      (container_bits != 8 && container_bits != 16))
    ThrowUserError("camera '" + id + "'", "pixel format",
                   "'" + format_name + "' is packed or not 8/16-bit (use Mono8-16 or unpacked Bayer)");
  if (container_bits == 16 && size >= frame.pixels.size() * 2) {
    std::memcpy(frame.pixels.data(), data, frame.pixels.size() * 2);
  } else if (container_bits == 8 && size >= frame.pixels.size()) {
    std::copy(data, data + frame.pixels.size(), frame.pixels.begin());
  } else {
    ThrowUserError("camera '" + id + "'", "acquisition", "frame smaller than its region (" + format_name + ")");
  }
  // Significant bits: the number in the format's name (Mono12 -> 12).
  const std::size_t digits = format_name.find_first_of("0123456789");
  frame.adc_bits = digits == std::string::npos ? container_bits : std::atoi(format_name.c_str() + digits);
  if (frame.adc_bits < 1 || frame.adc_bits > 16) frame.adc_bits = container_bits;
  frame.channel_names = {bayer ? format_name.substr(0, format_name.find_first_of("0123456789")) : std::string("Y")};
  frame.camera_timestamp_ns = arv_buffer_get_timestamp(buffer);
  if (arv_camera_is_feature_available(camera, "DeviceTemperature", nullptr))
    frame.sensor_temperature_c = arv_camera_get_float(camera, "DeviceTemperature", nullptr);
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
  impl_->carried = {};
  GError* error = nullptr;
  if (impl_->stream) g_object_unref(impl_->stream);
  impl_->stream = arv_camera_create_stream(impl_->camera, nullptr, nullptr, &error);
  Check(error, impl_->id, "stream");
  // Lost packets are asked for again (Aravis's default, stated here since a
  // frame is only kept whole): the camera resends them from its memory.
  if (ARV_IS_GV_STREAM(impl_->stream))
    g_object_set(impl_->stream, "socket-buffer", ARV_GV_STREAM_SOCKET_BUFFER_FIXED, "socket-buffer-size",
                 8 * 1024 * 1024, "packet-resend", ARV_GV_STREAM_PACKET_RESEND_ALWAYS, nullptr);
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
    ThrowUserError("camera '" + impl_->id + "'", "pixel format",
                   "does not offer '" + name + "' (it has: " + JoinComma(formats) + ")");
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
  gint x = 0, y = 0, width = 0, height = 0;
  arv_camera_get_region(impl_->camera, &x, &y, &width, &height, &error);
  Check(error, impl_->id, "region");
  const auto [wmax, hmax] = BinnedSensorSize(impl_->camera, impl_->id);
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
      ThrowUserError("camera '" + impl_->id + "'", "trigger",
                     "has no trigger source '" + wanted + "' (it has: " + JoinComma(sources) + ")");
    }
    // FrameStart on the rising edge of `wanted`, acquisition continuous (armed).
    arv_camera_set_trigger(impl_->camera, wanted.c_str(), &error);
    Check(error, impl_->id, "trigger");
  }
  trigger_ = trigger;
  trigger_source_ = source;
}

void AravisCamera::SetRegion(int x, int y, int width, int height, std::string_view field) {
  // Aravis's fake sets any region and then writes its frames past its buffer
  // (a segfault of capture at [0, 0, 65536, 65536]); a real camera may
  // refuse or clamp it. Checked here against what the camera reports.
  const auto [wmax, hmax] = BinnedSensorSize(impl_->camera, impl_->id);
  if (x < 0 || y < 0 || width < 1 || height < 1 || width > wmax - x || height > hmax - y) {
    const auto [dx, dy] = binning();
    ThrowUserError("camera '" + impl_->id + "'", field,
                   "[" + std::to_string(x) + ", " + std::to_string(y) + ", " + std::to_string(width) + ", " +
                       std::to_string(height) + "] reaches past the sensor, which is " + std::to_string(wmax) + " x " +
                       std::to_string(hmax) + " pixels at binning " + std::to_string(dx) + "x" + std::to_string(dy) +
                       " (x + width and y + height at most those)");
  }
  GError* error = nullptr;
  arv_camera_set_region(impl_->camera, x, y, width, height, &error);
  Check(error, impl_->id, "region");
  AllocateBuffers();
}

void AravisCamera::set_max_retakes(int retakes) {
  if (retakes < 0 || retakes > 100)
    ThrowUserError("camera '" + impl_->id + "'", "retakes",
                   "refuses " + std::to_string(retakes) + " (it takes 0 to 100)");
  max_retakes_ = retakes;
}

AravisCamera::StreamStatistics AravisCamera::stream_statistics() const {
  StreamStatistics s = impl_->carried;
  s.completed_frames += StreamCount(impl_->stream, "n_completed_buffers");
  s.failed_frames += StreamCount(impl_->stream, "n_failures");
  s.resend_requests += StreamCount(impl_->stream, "n_resend_requests");
  s.resent_packets += StreamCount(impl_->stream, "n_resent_packets");
  s.missing_packets += StreamCount(impl_->stream, "n_missing_packets");
  return s;
}

// A GigE stream that has given an incomplete frame can stay stuck: with
// Aravis's GigE fake at 10% packet loss, 1 run in 12 of a decay session
// under ASan saw every one of 31 retakes arrive incomplete, about 7 of 9
// packets missing each (tests/acquire/aravis_camera_test.cpp); on a fresh
// stream for each retake, none in 76 (docs/capture.md).
void AravisCamera::RenewStreamForRetake() {
  const StreamStatistics counts = stream_statistics();
  AllocateBuffers();
  impl_->carried = counts;
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
  return std::string("Aravis camera '") + impl_->id + "' (" + (vendor ? vendor : "?") + " " + (model ? model : "?") +
         ")";
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
  SetExposureAndGain(impl_->camera, impl_->id, exposure_s, gain);

  GError* error = nullptr;
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
  gint64 try_started_ns = 0;
  const StreamStatistics before = stream_statistics();
  const gint64 try_timeout_us = static_cast<gint64>((exposure_s + timeout_s_) * 1e6);
  ArvBuffer* buffer = nullptr;
  for (int retakes = 0;; ++retakes) {
    frame.t_start_s = clock_.now_s();
    try_started_ns = g_get_real_time() * 1000;
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
    buffer = PopThisFrame(impl_->stream, try_timeout_us, try_started_ns);
    arv_camera_stop_acquisition(impl_->camera, nullptr);
    if (buffer == nullptr && trigger_ == Trigger::kHardware)
      ThrowUserError("camera '" + impl_->id + "'", "acquisition",
                     "no frame within " + FormatShort(exposure_s + timeout_s_) + " s: the hardware trigger on '" +
                         trigger_source_ + "' did not fire (check its wiring)");
    if (buffer == nullptr)
      ThrowUserError("camera '" + impl_->id + "'", "acquisition", "no frame arrived in time (disconnected?)");
    const std::string incomplete = WhyIncomplete(buffer);
    if (incomplete.empty()) {
      frame.retakes = retakes;
      break;
    }
    arv_stream_push_buffer(impl_->stream, buffer);
    if (retakes == max_retakes_) {
      const StreamStatistics now = stream_statistics();
      ThrowUserError("camera '" + impl_->id + "'", "acquisition",
                     std::to_string(retakes + 1) + " tries in a row arrived incomplete (the last: " + incomplete +
                         "; " + std::to_string(now.missing_packets - before.missing_packets) + " packets missing, " +
                         std::to_string(now.resent_packets - before.resent_packets) + " resent): check the link");
    }
    if (ARV_IS_GV_STREAM(impl_->stream)) RenewStreamForRetake();
  }
  frame.packets_resent = stream_statistics().resent_packets - before.resent_packets;
  // The buffer goes back to the stream on every way out.
  struct Requeue {
    ArvStream* stream;
    ArvBuffer* buffer;
    ~Requeue() { arv_stream_push_buffer(stream, buffer); }
  } requeue{impl_->stream, buffer};
  ReadFrame(impl_->camera, impl_->id, buffer, frame);
  last_frame_id_ = arv_buffer_get_frame_id(buffer);
  last_camera_timestamp_ns_ = arv_buffer_get_timestamp(buffer);
  return frame;
}

}  // namespace phos
