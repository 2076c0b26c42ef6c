#include "m3dp/toolpath/gcode.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <map>
#include <optional>

#include "m3dp/core/text.hpp"

namespace m3dp::toolpath {

namespace fs = std::filesystem;

namespace {

constexpr double kPiDouble = 3.14159265358979323846;

/// One parsed line: its command (e.g. "G1") and the values of its parameter letters.
struct Words {
  std::string command;
  std::array<std::optional<double>, 26> value;  // indexed by letter − 'A'
  [[nodiscard]] const std::optional<double>& operator[](char letter) const { return value[letter - 'A']; }
};

class Parser {
 public:
  Parser(const fs::path& file, const GcodeSettings& settings) : file_(file), settings_(settings) {
    // G-code units per minute: the default is a world speed, so it is unscaled back to G-code units.
    feed_rate_ = settings.default_feed_rate / (settings.length_scale * settings.geometry_scale) * 60;
  }

  GcodeProgram parse(std::string_view text) {
    for_each_line(text, [this](std::string_view line, int line_number) { parse_line(line, line_number); });
    for (const auto& [command, skipped] : skipped_)
      program_.warnings.push_back(Diagnostic{SourceLocation{file_.string(), skipped.first_line},
                                             fmt::format("{} is not simulated (only moves, arcs, dwells and modes are); "
                                                         "skipped ({} time{})",
                                                         command, skipped.count, skipped.count == 1 ? "" : "s")});
    std::sort(program_.warnings.begin(), program_.warnings.end(),
              [](const Diagnostic& a, const Diagnostic& b) { return a.location.line < b.location.line; });
    program_.layers = layer_ + 1;
    return std::move(program_);
  }

 private:
  [[noreturn]] void fail(int line, const std::string& message) const {
    throw InputError(SourceLocation{file_.string(), line}, message);
  }

  void read_comment(std::string_view comment) {
    while (!comment.empty() && (comment.front() == ' ' || comment.front() == '\t')) comment.remove_prefix(1);
    if (comment.rfind("LAYER_CHANGE", 0) == 0 || comment.rfind("LAYER:", 0) == 0) ++layer_;
    if (comment.rfind("TYPE:", 0) == 0) {
      feature_ = std::string(comment.substr(5));
      while (!feature_.empty() && (feature_.back() == '\r' || feature_.back() == ' ')) feature_.pop_back();
    }
  }

  void parse_line(std::string_view line, int line_number) {
    // Comments: ';' to the end of the line, '(' … ')' inside it.
    if (const std::size_t semicolon = line.find(';'); semicolon != std::string_view::npos) {
      read_comment(line.substr(semicolon + 1));
      line = line.substr(0, semicolon);
    }
    std::string code;
    code.reserve(line.size());
    bool in_parenthesis = false;
    for (const char c : line) {
      if (c == '(') in_parenthesis = true;
      else if (c == ')') in_parenthesis = false;
      else if (!in_parenthesis && c != '\r') code += c;
    }
    if (const std::size_t star = code.find('*'); star != std::string::npos) code.resize(star);  // checksum
    Words words;
    std::size_t i = 0;
    auto skip_blanks = [&] {
      while (i < code.size() && (code[i] == ' ' || code[i] == '\t')) ++i;
    };
    skip_blanks();
    while (i < code.size()) {
      const char letter = static_cast<char>(std::toupper(static_cast<unsigned char>(code[i])));
      if (letter < 'A' || letter > 'Z')
        fail(line_number, fmt::format("unexpected '{}' in '{}'; expected a letter followed by a number", code[i], trimmed(code)));
      ++i;
      skip_blanks();
      std::size_t number_end = i;
      while (number_end < code.size() && (std::isdigit(static_cast<unsigned char>(code[number_end])) || code[number_end] == '.' ||
                                          code[number_end] == '-' || code[number_end] == '+'))
        ++number_end;
      const std::string number = code.substr(i, number_end - i);
      double value = 0;
      const auto [end, error] = std::from_chars(number.data(), number.data() + number.size(), value);
      if (number.empty() || error != std::errc() || end != number.data() + number.size()) {
        // Parameterless words (e.g. "G28 X" = home X) carry no number: allowed only after a command,
        // and only as a whole word.
        const bool whole_word = number_end == code.size() || code[number_end] == ' ' || code[number_end] == '\t';
        if (!words.command.empty() && number.empty() && whole_word && letter != 'G' && letter != 'M') {
          words.value[letter - 'A'] = std::nan("");
          i = number_end;
          skip_blanks();
          continue;
        }
        std::size_t word_end = number_end;
        while (word_end < code.size() && code[word_end] != ' ' && code[word_end] != '\t') ++word_end;
        fail(line_number, fmt::format("'{}{}' in '{}' is not a number", letter, code.substr(i, word_end - i), trimmed(code)));
      }
      // "X1e3": firmwares that read numbers with strtod take 1000, G-code's grammar X1 and E3 (E is
      // the extruder's axis). Either reading could be what was meant: refused, never guessed.
      if (number_end < code.size() && (code[number_end] == 'e' || code[number_end] == 'E')) {
        std::size_t digit = number_end + 1;
        if (digit < code.size() && (code[digit] == '+' || code[digit] == '-')) ++digit;
        if (digit < code.size() && std::isdigit(static_cast<unsigned char>(code[digit]))) {
          std::size_t word_end = digit;
          while (word_end < code.size() && std::isdigit(static_cast<unsigned char>(code[word_end]))) ++word_end;
          fail(line_number, fmt::format("'{}{}' in '{}' is ambiguous: {} with an exponent, or {}{} then {} (E is the extruder's axis); "
                                        "write the number out, or put a space before the {}",
                                        letter, code.substr(i, word_end - i), trimmed(code), number, letter, number,
                                        code.substr(number_end, word_end - number_end), code[number_end]));
        }
      }
      i = number_end;
      skip_blanks();
      if (letter == 'N' && words.command.empty()) continue;  // line number
      if ((letter == 'G' || letter == 'M' || letter == 'T') && words.command.empty()) {
        words.command = fmt::format("{}{}", letter, number);
        continue;
      }
      if (words.command.empty())
        fail(line_number, fmt::format("'{}' has parameters but no G or M command", trimmed(code)));
      words.value[letter - 'A'] = value;
    }
    if (!words.command.empty()) execute(words, line_number);
  }

  static std::string trimmed(std::string text) {
    while (!text.empty() && (text.back() == ' ' || text.back() == '\t')) text.pop_back();
    std::size_t first = text.find_first_not_of(" \t");
    return first == std::string::npos ? std::string() : text.substr(first);
  }

  double number(const Words& words, char letter, int line_number) const {
    const auto& value = words[letter];
    if (value && std::isnan(*value)) fail(line_number, fmt::format("{} needs a number after {}", words.command, letter));
    return value.value_or(0);
  }

  void execute(const Words& words, int line_number) {
    const std::string& command = words.command;
    if (command == "G0" || command == "G1" || command == "G00" || command == "G01") return linear_move(words, line_number);
    if (command == "G2" || command == "G3" || command == "G02" || command == "G03") return arc_move(words, line_number);
    if (command == "G4" || command == "G04") return dwell(words, line_number);
    if (command == "G90") { absolute_xyz_ = true; absolute_e_ = true; return; }  // RepRap: G90 also sets E absolute
    if (command == "G91") { absolute_xyz_ = false; absolute_e_ = false; return; }
    if (command == "M82") { absolute_e_ = true; return; }
    if (command == "M83") { absolute_e_ = false; return; }
    if (command == "G20") { unit_to_mm_ = 25.4; return; }
    if (command == "G21") { unit_to_mm_ = 1.0; return; }
    if (command == "G92") {
      for (int axis = 0; axis < 3; ++axis)
        if (words["XYZ"[axis]]) position_[axis] = number(words, "XYZ"[axis], line_number) * unit_to_mm_;
      if (words['E']) e_ = number(words, 'E', line_number) * unit_to_mm_;
      if (!words['X'] && !words['Y'] && !words['Z'] && !words['E']) { position_ = {0, 0, 0}; e_ = 0; }
      return;
    }
    auto& skipped = skipped_[command];
    if (skipped.count++ == 0) skipped.first_line = line_number;
  }

  /// Target of a move in mm (G-code frame) and its E, from the words and the modes.
  std::array<double, 3> target_of(const Words& words, int line_number) const {
    std::array<double, 3> target = position_;
    for (int axis = 0; axis < 3; ++axis)
      if (words["XYZ"[axis]]) {
        const double value = number(words, "XYZ"[axis], line_number) * unit_to_mm_;
        target[axis] = absolute_xyz_ ? value : position_[axis] + value;
      }
    return target;
  }
  double e_target(const Words& words, int line_number) const {
    if (!words['E']) return e_;
    const double value = number(words, 'E', line_number) * unit_to_mm_;
    return absolute_e_ ? value : e_ + value;
  }
  void update_feed_rate(const Words& words, int line_number) {
    if (!words['F']) return;
    const double feed = number(words, 'F', line_number) * unit_to_mm_;
    if (!(feed > 0)) fail(line_number, fmt::format("F{} : the feed rate must be > 0 (mm/min)", feed));
    feed_rate_ = feed;
  }

  /// G-code millimetres → world metres through the placement.
  Vec3 world(const std::array<double, 3>& millimetres) const {
    const double scale = settings_.length_scale * settings_.geometry_scale;
    return settings_.placement.apply(Vec3(static_cast<Real>(millimetres[0] * scale), static_cast<Real>(millimetres[1] * scale),
                                          static_cast<Real>(millimetres[2] * scale)));
  }

  double volume_of(double extrusion_mm) const {
    if (extrusion_mm <= 0) return 0;
    const double mm3 = settings_.volumetric_extrusion
                           ? extrusion_mm
                           : extrusion_mm * kPiDouble * std::pow(settings_.filament_diameter * 1e3, 2) / 4;
    return mm3 * 1e-9 * std::pow(static_cast<double>(settings_.geometry_scale), 3);  // m³
  }

  /// Adds one straight piece from position_ to `target` with `extrusion` E units.
  void add_piece(const std::array<double, 3>& target, double extrusion, int line_number) {
    const double length_mm = std::sqrt(std::pow(target[0] - position_[0], 2) + std::pow(target[1] - position_[1], 2) +
                                       std::pow(target[2] - position_[2], 2));
    GcodeMove move;
    move.start = world(position_);
    move.end = world(target);
    move.extrusion = extrusion;
    move.layer = layer_;
    move.line = line_number;
    move.feature = feature_;
    // Time at the feed rate; an E-only move (retraction) runs the filament at that rate in place.
    const double travel_mm = length_mm > 0 ? length_mm : std::abs(extrusion);
    move.duration = travel_mm / feed_rate_ * 60;
    move.dwell = length_mm == 0;
    move.material_volume = length_mm > 0 ? volume_of(extrusion) : 0;
    program_.net_extrusion += extrusion;
    program_.material_volume += move.material_volume;
    program_.duration += move.duration;
    if (move.duration > 0) program_.moves.push_back(std::move(move));
    position_ = target;
  }

  void linear_move(const Words& words, int line_number) {
    update_feed_rate(words, line_number);
    const auto target = target_of(words, line_number);
    const double e_target_value = e_target(words, line_number);
    add_piece(target, e_target_value - e_, line_number);
    e_ = e_target_value;
  }

  void arc_move(const Words& words, int line_number) {
    update_feed_rate(words, line_number);
    const bool clockwise = words.command == "G2" || words.command == "G02";
    const auto target = target_of(words, line_number);
    const double e_target_value = e_target(words, line_number);
    const double sx = position_[0], sy = position_[1];
    double cx = 0, cy = 0;
    if (words['I'] || words['J']) {
      cx = sx + number(words, 'I', line_number) * unit_to_mm_;
      cy = sy + number(words, 'J', line_number) * unit_to_mm_;
    } else if (words['R']) {
      // Centre from the radius: on the chord's bisector; R < 0 picks the larger arc.
      const double radius = number(words, 'R', line_number) * unit_to_mm_;
      const double dx = target[0] - sx, dy = target[1] - sy, chord = std::hypot(dx, dy);
      if (chord == 0 || std::abs(radius) < chord / 2)
        fail(line_number, fmt::format("{} R{}: the radius is shorter than half the chord ({} mm)", words.command, radius, chord / 2));
      const double offset = std::sqrt(radius * radius - chord * chord / 4) * ((clockwise == (radius > 0)) ? -1 : 1);
      cx = sx + dx / 2 - offset * dy / chord;
      cy = sy + dy / 2 + offset * dx / chord;
    } else {
      fail(line_number, fmt::format("{} needs a centre (I and J) or a radius (R)", words.command));
    }
    const double radius = std::hypot(sx - cx, sy - cy);
    const double end_radius = std::hypot(target[0] - cx, target[1] - cy);
    if (radius == 0 || std::abs(end_radius - radius) > 0.01 * radius + 0.02)
      fail(line_number, fmt::format("{}: start and end are not on one circle around ({}, {}) (radii {} and {} mm)", words.command,
                                    cx, cy, radius, end_radius));
    const double start_angle = std::atan2(sy - cy, sx - cx);
    double sweep = std::atan2(target[1] - cy, target[0] - cx) - start_angle;
    if (clockwise && sweep >= 0) sweep -= 2 * kPiDouble;
    if (!clockwise && sweep <= 0) sweep += 2 * kPiDouble;
    const double arc_mm = std::abs(sweep) * radius;
    const int pieces = std::max(
        1, static_cast<int>(std::ceil(arc_mm * settings_.length_scale * settings_.geometry_scale / settings_.arc_segment_length)));
    const double start_z = position_[2], total_e = e_target_value - e_;
    for (int k = 1; k <= pieces; ++k) {
      const double fraction = double(k) / pieces;
      const double angle = start_angle + sweep * fraction;
      std::array<double, 3> point{cx + radius * std::cos(angle), cy + radius * std::sin(angle),
                                  start_z + (target[2] - start_z) * fraction};
      if (k == pieces) point = target;
      add_piece(point, total_e / pieces, line_number);
    }
    e_ = e_target_value;
  }

  void dwell(const Words& words, int line_number) {
    // G4 P<milliseconds> or S<seconds>.
    const double seconds = words['S'] ? number(words, 'S', line_number) : number(words, 'P', line_number) / 1000;
    if (seconds < 0) fail(line_number, "G4 needs a time >= 0 (P in ms or S in s)");
    if (seconds == 0) return;
    GcodeMove move;
    move.start = move.end = world(position_);
    move.duration = seconds;
    move.dwell = true;
    move.layer = layer_;
    move.line = line_number;
    move.feature = feature_;
    program_.duration += seconds;
    program_.moves.push_back(std::move(move));
  }

  struct Skipped {
    int first_line = 0;
    int count = 0;
  };

  fs::path file_;
  GcodeSettings settings_;
  GcodeProgram program_;
  std::array<double, 3> position_{0, 0, 0};  // mm, G-code frame
  double e_ = 0;                              // E units
  double feed_rate_;                          // G-code mm/min
  double unit_to_mm_ = 1;
  bool absolute_xyz_ = true, absolute_e_ = true;
  int layer_ = -1;
  std::string feature_;
  std::map<std::string, Skipped> skipped_;
};

}  // namespace

std::vector<PathSegment> GcodeProgram::path_segments() const {
  std::vector<PathSegment> segments;
  segments.reserve(moves.size());
  for (const GcodeMove& move : moves) {
    PathSegment segment;
    segment.curve = LineCurve{move.start, move.end};
    if (move.dwell) {
      segment.dwell = static_cast<Real>(move.duration);
      segment.extrude = false;
    } else {
      segment.speed = static_cast<Real>((move.end - move.start).norm() / move.duration);
      segment.extrude = move.extruding();
      segment.volume_rate = static_cast<Real>(move.material_volume / move.duration);
    }
    segments.push_back(std::move(segment));
  }
  return segments;
}

GcodeProgram parse_gcode(std::string_view text, const fs::path& file, const GcodeSettings& settings) {
  if (!(settings.length_scale > 0) || !(settings.filament_diameter > 0) || !(settings.default_feed_rate > 0) ||
      !(settings.arc_segment_length > 0) || !(settings.geometry_scale > 0))
    throw Error("G-code settings: length_scale, geometry_scale, filament_diameter, default_feed_rate and arc_segment_length "
                "must be > 0");
  return Parser(file, settings).parse(text);
}

GcodeProgram read_gcode(const fs::path& file, const GcodeSettings& settings) {
  return parse_gcode(read_text_file(file, "G-code file"), file, settings);
}

}  // namespace m3dp::toolpath
