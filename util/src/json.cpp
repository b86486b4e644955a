#include "phos/util/json.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <set>
#include <sstream>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include "phos/util/error.h"
#include "phos/util/format.h"

namespace phos {

std::string ReadFileText(const std::filesystem::path& path, std::uintmax_t max_bytes) {
  const std::string where = path.string();
  // O_NONBLOCK: opening a FIFO for reading would otherwise wait for a writer.
  const int fd = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) ThrowUserError(where, "", std::string("cannot open the file for reading (") + std::strerror(errno) + ")");
  struct FdCloser {
    int fd;
    ~FdCloser() { ::close(fd); }
  } closer{fd};
  struct stat info {};
  if (::fstat(fd, &info) != 0)
    ThrowUserError(where, "", std::string("cannot read the file (") + std::strerror(errno) + ")");
  if (S_ISDIR(info.st_mode)) ThrowUserError(where, "", "is a folder, not a file");
  if (!S_ISREG(info.st_mode))
    ThrowUserError(where, "", "not a regular file (a FIFO, socket or device); phos reads only regular files");
  const auto too_large = [&](std::uintmax_t bytes) {
    ThrowUserError(where, "",
                   "the file has " + std::to_string(bytes) + " bytes, more than the limit of " +
                       std::to_string(max_bytes) + " bytes");
  };
  if (static_cast<std::uintmax_t>(info.st_size) > max_bytes) too_large(static_cast<std::uintmax_t>(info.st_size));
  std::string text(static_cast<std::size_t>(info.st_size), '\0');
  std::size_t have = 0;
  while (true) {  // the file may have grown or shrunk since fstat: read to its end, within the limit
    if (have == text.size()) {
      if (text.size() >= max_bytes) {
        char probe;
        const ssize_t n = ::read(fd, &probe, 1);
        if (n > 0) too_large(max_bytes + 1);
        if (n == 0) break;
        if (errno == EINTR) continue;
        ThrowUserError(where, "", std::string("reading failed (") + std::strerror(errno) + ")");
      }
      text.resize(static_cast<std::size_t>(
          std::min<std::uintmax_t>(max_bytes, std::max<std::uintmax_t>(4096, 2 * text.size()))));
    }
    const ssize_t n = ::read(fd, text.data() + have, text.size() - have);
    if (n == 0) break;
    if (n < 0) {
      if (errno == EINTR) continue;
      ThrowUserError(where, "", std::string("reading failed (") + std::strerror(errno) + ")");
    }
    have += static_cast<std::size_t>(n);
  }
  text.resize(have);
  return text;
}

void CheckJsonNesting(std::string_view text, const std::string& source) {
  int depth = 0;
  bool in_string = false;
  for (std::size_t i = 0; i < text.size(); ++i) {
    const char c = text[i];
    if (in_string) {
      if (c == '\\')
        ++i;  // the escaped character, a quote or a backslash, is not the string's end
      else if (c == '"')
        in_string = false;
    } else if (c == '"') {
      in_string = true;
    } else if (c == '[' || c == '{') {
      if (++depth > kMaxJsonNesting)
        ThrowUserError(source, "",
                       "arrays and objects nested more than the limit of " + std::to_string(kMaxJsonNesting) +
                           " levels deep (at byte " + std::to_string(i) + ")");
    } else if ((c == ']' || c == '}') && depth > 0) {
      --depth;
    }
  }
}

namespace {

// Finds a key given twice in one object while nlohmann parses (its DOM keeps
// the last in silence): one frame per open array or object, with the keys
// seen so far, the current key or element index for the path in the message.
class DuplicateKeyCheck {
 public:
  explicit DuplicateKeyCheck(const std::string& source) : source_(source) {}

  bool operator()(int, nlohmann::json::parse_event_t event, nlohmann::json& parsed) {
    using Event = nlohmann::json::parse_event_t;
    if (event == Event::object_start || event == Event::array_start || event == Event::value) StartElement();
    switch (event) {
      case Event::object_start: frames_.push_back({true, {}, "", -1}); break;
      case Event::array_start: frames_.push_back({false, {}, "", -1}); break;
      case Event::object_end:
      case Event::array_end:
        if (!frames_.empty()) frames_.pop_back();
        break;
      case Event::key: {
        Frame& frame = frames_.back();
        frame.key = parsed.get<std::string>();
        if (!frame.keys.insert(frame.key).second) ThrowUserError(source_, Path(), "the key is given twice");
        break;
      }
      case Event::value: break;
    }
    return true;
  }

 private:
  struct Frame {
    bool object;
    std::set<std::string> keys;
    std::string key;  // an object's current member
    long index;       // an array's current element
  };

  void StartElement() {
    if (!frames_.empty() && !frames_.back().object) ++frames_.back().index;
  }

  std::string Path() const {
    std::string path;
    for (const Frame& frame : frames_) {
      if (frame.object)
        path += (path.empty() ? "" : ".") + frame.key;
      else
        path += "[" + std::to_string(frame.index) + "]";
    }
    return path;
  }

  const std::string& source_;
  std::vector<Frame> frames_;
};

}  // namespace

nlohmann::json ParseJsonText(std::string_view text, const std::string& source) {
  CheckJsonNesting(text, source);
  try {
    return nlohmann::json::parse(text, DuplicateKeyCheck(source));
  } catch (const nlohmann::json::exception& e) {
    // Drop nlohmann's "[json.exception.parse_error.101] " prefix: the user
    // needs the position and the reason.
    std::string what = e.what();
    if (auto close = what.find("] "); what.rfind("[json.exception", 0) == 0 && close != std::string::npos)
      what = what.substr(close + 2);
    ThrowUserError(source, "", "not valid JSON: " + what);
  }
}

nlohmann::json ReadJsonFile(const std::filesystem::path& path) {
  return ParseJsonText(ReadFileText(path), path.string());
}

std::vector<nlohmann::json> ReadJsonLines(const std::filesystem::path& path) {
  std::vector<nlohmann::json> records;
  std::ifstream in(path);
  for (std::string text; std::getline(in, text);) {
    nlohmann::json record = nlohmann::json::parse(text, nullptr, false);
    if (!record.is_discarded() && record.is_object()) records.push_back(std::move(record));
  }
  return records;
}

std::string DescribeJson(const nlohmann::json& value) {
  switch (value.type()) {
    case nlohmann::json::value_t::null: return "null";
    case nlohmann::json::value_t::object: return "an object";
    case nlohmann::json::value_t::array: return "an array";
    case nlohmann::json::value_t::boolean: return value.get<bool>() ? "true" : "false";
    case nlohmann::json::value_t::string: {
      std::string s = value.get<std::string>();
      if (s.size() > 40) s = s.substr(0, 37) + "...";
      return "\"" + s + "\"";
    }
    default:
      if (value.is_number()) return FormatDouble(value.get<double>());
      return value.dump();
  }
}

JsonField::JsonField(const nlohmann::json& value, std::string source, std::string path)
    : value_(&value), source_(std::move(source)), path_(std::move(path)) {}

void JsonField::Fail(std::string_view message) const {
  ThrowUserError(source_, path_.empty() ? std::string_view("(top level)") : std::string_view(path_), message);
}

void JsonField::RequireObject() const {
  if (!value_->is_object()) Fail("expected an object, got " + DescribeJson(*value_));
}

bool JsonField::Has(std::string_view key) const {
  RequireObject();
  return value_->contains(key);
}

JsonField JsonField::operator[](std::string_view key) const {
  RequireObject();
  std::string child = path_.empty() ? std::string(key) : path_ + "." + std::string(key);
  auto it = value_->find(key);
  if (it == value_->end()) ThrowUserError(source_, child, "missing (required)");
  return JsonField(*it, source_, child);
}

std::optional<JsonField> JsonField::Optional(std::string_view key) const {
  RequireObject();
  if (!value_->contains(key)) return std::nullopt;
  return (*this)[key];
}

std::size_t JsonField::ArraySize() const {
  if (!value_->is_array()) Fail("expected an array, got " + DescribeJson(*value_));
  return value_->size();
}

JsonField JsonField::At(std::size_t index) const {
  if (index >= ArraySize()) Fail("index " + std::to_string(index) + " out of range");
  return JsonField((*value_)[index], source_, path_ + "[" + std::to_string(index) + "]");
}

double JsonField::Number() const {
  if (!value_->is_number()) Fail("expected a number, got " + DescribeJson(*value_));
  double v = value_->get<double>();
  if (!std::isfinite(v)) Fail("expected a finite number, got " + FormatDouble(v));
  return v;
}

double JsonField::NumberAtLeast(double lower) const {
  double v = Number();
  if (v < lower) Fail("expected a number >= " + FormatDouble(lower) + ", got " + FormatDouble(v));
  return v;
}

double JsonField::NumberInRange(double lower, double upper) const {
  double v = Number();
  if (v < lower || v > upper)
    Fail("expected a number in [" + FormatDouble(lower) + ", " + FormatDouble(upper) + "], got " + FormatDouble(v));
  return v;
}

bool JsonField::Boolean() const {
  if (!value_->is_boolean()) Fail("expected true or false, got " + DescribeJson(*value_));
  return value_->get<bool>();
}

int JsonField::Integer(int lower, int upper) const {
  if (!value_->is_number_integer() &&
      !(value_->is_number() && std::floor(value_->get<double>()) == value_->get<double>()))
    Fail("expected a whole number, got " + DescribeJson(*value_));
  double v = value_->get<double>();
  if (v < lower || v > upper)
    Fail("expected a whole number from " + std::to_string(lower) + " to " + std::to_string(upper) + ", got " +
         FormatDouble(v));
  return static_cast<int>(v);
}

std::string JsonField::String() const {
  if (!value_->is_string()) Fail("expected a string, got " + DescribeJson(*value_));
  return value_->get<std::string>();
}

std::string JsonField::NonEmptyString() const {
  std::string s = String();
  if (s.empty()) Fail("expected a non-empty string");
  return s;
}

std::vector<double> JsonField::NumberArray(std::size_t size, double lower) const {
  std::size_t n = ArraySize();
  if (size != 0 && n != size)
    Fail("expected " + std::to_string(size) + " values (one per band), got " + std::to_string(n));
  std::vector<double> values(n);
  for (std::size_t i = 0; i < n; ++i) values[i] = At(i).NumberAtLeast(lower);
  return values;
}

void JsonField::RejectUnknownKeys(std::initializer_list<std::string_view> known) const {
  RequireObject();
  for (auto it = value_->begin(); it != value_->end(); ++it) {
    bool found = false;
    for (std::string_view k : known) found = found || it.key() == k;
    if (!found) {
      const std::string list = JoinComma(known, [](std::string_view k) { return std::string(k); });
      std::string child = path_.empty() ? it.key() : path_ + "." + it.key();
      ThrowUserError(source_, child, "unknown field (expected one of: " + list + ")");
    }
  }
}

}  // namespace phos
