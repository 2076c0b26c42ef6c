#include "m3dp/toolpath/gcode.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <map>
#include <optional>
#include <utility>

#include "m3dp/core/text.hpp"

namespace m3dp::toolpath {

namespace fs = std::filesystem;

namespace {

constexpr double kPiDouble = 3.14159265358979323846;
constexpr double kMaxArcPieces = 1e6;  // lines one arc is split into: more is a centre far off, not a print
/// The fastest nozzle a feed rate may ask for (m/s in the world): beyond any printer or robot (a
/// desktop printer's 1 m/s, a gantry's or an arm's few m/s); a faster F is a typo, whose moves would
/// take no time and lay their material in no time.
constexpr double kMaxFeedSpeed = 10;
/// What E is read as when neither the file nor the scene says how thick the filament is.
constexpr double kAssumedFilamentMm = 1.75, kOtherFilamentMm = 2.85;

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
    read_slicer_settings(text);
    for_each_line(text, [this](std::string_view line, int line_number) { parse_line(line, line_number); });
    for (const auto& [command, skipped] : skipped_) {
      const bool macro = command.size() > 1 && !std::isdigit(static_cast<unsigned char>(command[1]));
      program_.warnings.push_back(Diagnostic{
          SourceLocation{file_.string(), skipped.first_line},
          fmt::format("{} {} not simulated (only moves, arcs, dwells and modes are); skipped ({} time{})",
                      command, macro ? "is a firmware macro (Klipper, RepRapFirmware), " : "is", skipped.count,
                      skipped.count == 1 ? "" : "s")});
    }
    std::sort(program_.warnings.begin(), program_.warnings.end(),
              [](const Diagnostic& a, const Diagnostic& b) { return a.location.line < b.location.line; });
    program_.layers = layer_ + 1;
    return std::move(program_);
  }

 private:
  [[noreturn]] void fail(int line, const std::string& message) const {
    throw InputError(SourceLocation{file_.string(), line}, message);
  }

  /// The slicer's own record of how it counted E, read before any move: PrusaSlicer, Slic3r and their
  /// forks end the file with their settings ("; use_volumetric_e = 1", "; filament_diameter = 2.85",
  /// "; extrusion_axis = A"), Cura starts it with ";FLAVOR:UltiGCode" (E in mm³) and ends it with its
  /// changed settings (";SETTING_3 … material_diameter = 2.85 …"), Simplify3D lists
  /// ";   filamentDiameters,2.85|…", KISSlicer "; fiber_dia_mm = 2.85", and RepRapFirmware's
  /// "M404 N2.85" tells the printer. The file is followed where the scene says nothing; where the scene
  /// says otherwise it is refused, since one of the two is wrong and the material would be off by their
  /// ratio; where neither says, 1.75 mm is assumed and the first extruding move warns so.
  void read_slicer_settings(std::string_view text) {
    std::optional<bool> file_volumetric;
    std::optional<double> file_diameter;
    int volumetric_line = 0, diameter_line = 0, flavor_line = 0;
    std::optional<char> file_axis;
    std::string flavor, cura_settings;
    auto take_diameter = [&](std::string_view value, int line_number) {
      double diameter = 0;  // mm; the first extruder's ("1.75,1.75" or "1.75|1.75" for two)
      const std::string_view first = value.substr(0, value.find_first_of(",|"));
      const auto [end, error] = std::from_chars(first.data(), first.data() + first.size(), diameter);
      if (error == std::errc() && diameter > 0 && std::isfinite(diameter)) {
        file_diameter = diameter;
        diameter_line = line_number;
      }
    };
    for_each_line(text, [&](std::string_view line, int line_number) {
      while (!line.empty() && (line.back() == '\r' || line.back() == ' ')) line.remove_suffix(1);
      if (line.rfind("M404 ", 0) == 0 && line.find('N') != std::string_view::npos) {  // RepRapFirmware's filament width
        take_diameter(line.substr(line.find('N') + 1), line_number);
        return;
      }
      if (line.empty() || line.front() != ';') return;
      line.remove_prefix(1);
      if (line.rfind("SETTING_3 ", 0) == 0) {  // Cura's changed settings, JSON cut into lines
        cura_settings += line.substr(10);
        if (const std::size_t at = cura_settings.find("material_diameter = "); at != std::string::npos && !file_diameter) {
          const std::size_t start = at + 20, stop = cura_settings.find("\\n", start);
          if (stop != std::string::npos) take_diameter(std::string_view(cura_settings).substr(start, stop - start), line_number);
        }
        return;
      }
      if (const std::size_t at = line.find("filamentDiameters,"); at != std::string_view::npos) {  // Simplify3D
        take_diameter(line.substr(at + 18), line_number);
        return;
      }
      while (!line.empty() && (line.back() == '\r' || line.back() == ' ')) line.remove_suffix(1);
      while (!line.empty() && line.front() == ' ') line.remove_prefix(1);
      if (line == "FLAVOR:UltiGCode") {
        file_volumetric = true;
        volumetric_line = line_number;
        return;
      }
      const std::size_t equals = line.find(" = ");
      if (equals == std::string_view::npos) return;
      const std::string_view key = line.substr(0, equals), value = line.substr(equals + 3);
      if (key == "use_volumetric_e") {
        file_volumetric = value == "1";
        volumetric_line = line_number;
      } else if (key == "filament_diameter" || key == "fiber_dia_mm") {
        take_diameter(value, line_number);
      } else if (key == "extrusion_axis" && value.size() == 1 && std::isalpha(static_cast<unsigned char>(value[0]))) {
        file_axis = static_cast<char>(std::toupper(static_cast<unsigned char>(value[0])));
      } else if (key == "gcode_flavor") {
        flavor = std::string(value);
        flavor_line = line_number;
      }
    });
    // The slicers put mach3's and machinekit's extrusion on A whatever extrusion_axis says.
    extrusion_axis_ = flavor == "mach3" || flavor == "machinekit" ? 'A' : file_axis.value_or('E');
    if (flavor == "no-extrusion")
      fail(flavor_line, "the slicer wrote this file without extrusion (gcode_flavor = no-extrusion): it would print nothing; "
                        "slice it with the flavour of an extruding printer");
    volumetric_ = settings_.volumetric_extrusion.value_or(file_volumetric.value_or(false));
    if (settings_.volumetric_extrusion && file_volumetric && *settings_.volumetric_extrusion != *file_volumetric)
      fail(volumetric_line,
           fmt::format("the slicer wrote E as {} but the scene says {}: one of the two is wrong and the material would be off by "
                       "the filament's cross-section; remove <volumetric_extrusion> from the scene to follow the file",
                       *file_volumetric ? "mm³ of material (volumetric E)" : "mm of filament",
                       *settings_.volumetric_extrusion ? "volumetric E" : "mm of filament"));
    // The scene's diameter to 6 digits: a float's 1.75e-3 m is 1.7500000540 mm.
    filament_diameter_mm_ = settings_.filament_diameter ? std::round(double(*settings_.filament_diameter) * 1e9) / 1e6
                                                        : file_diameter.value_or(kAssumedFilamentMm);
    diameter_assumed_ = !volumetric_ && !settings_.filament_diameter && !file_diameter;
    if (!volumetric_ && settings_.filament_diameter && file_diameter &&
        std::abs(*file_diameter / filament_diameter_mm_ - 1) > 1e-3)
      fail(diameter_line,
           fmt::format("the slicer counted E in mm of {} mm filament but the scene says {} mm: the material would be {:.3g} times "
                       "what the slicer meant; remove <filament_diameter> from the scene to follow the file, or slice for {} mm",
                       *file_diameter, filament_diameter_mm_, std::pow(filament_diameter_mm_ / *file_diameter, 2), filament_diameter_mm_));
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
    // A firmware macro (Klipper's PRINT_START BED=60, EXCLUDE_OBJECT_START NAME=…): a name, not a
    // letter and a number. It may do anything on the printer; here it is skipped with a warning.
    if (i + 1 < code.size() && std::isalpha(static_cast<unsigned char>(code[i])) &&
        (std::isalpha(static_cast<unsigned char>(code[i + 1])) || code[i + 1] == '_')) {
      std::size_t name_end = i;
      while (name_end < code.size() && code[name_end] != ' ' && code[name_end] != '\t') ++name_end;
      std::string name = code.substr(i, name_end - i);
      for (char& c : name) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
      auto& skipped = skipped_[name];
      if (skipped.count++ == 0) skipped.first_line = line_number;
      return;
    }
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
      // "X+30": a sign from_chars does not take (it takes '-' only).
      const std::size_t digits = !number.empty() && number[0] == '+' ? 1 : 0;
      double value = 0;
      const auto [end, error] = std::from_chars(number.data() + digits, number.data() + number.size(), value);
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
        // A command that does not move the nozzle or change how moves are read is skipped whole:
        // its parameters may be free text (M117 Printing…, M862.3 P "MK3S", M115 U3.12) or axis
        // letters alone (M84 X Y E).
        if (!is_read(words.command)) {
          auto& skipped = skipped_[words.command];
          if (skipped.count++ == 0) skipped.first_line = line_number;
          return;
        }
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

  /// The commands this reader follows; every other one is skipped with a warning.
  static bool is_read(std::string_view command) {
    static constexpr std::array<std::string_view, 23> kRead{"G0",  "G1",  "G00", "G01", "G2",  "G3",  "G02",  "G03",
                                                             "G4",  "G04", "G90", "G91", "M82", "M83", "G20",  "G21",
                                                             "G92", "G17", "G18", "G19", "M404", "M220", "M221"};
    return std::find(kRead.begin(), kRead.end(), command) != kRead.end();
  }

  void execute(const Words& words, int line_number) {
    const std::string& command = words.command;
    if (command == "G17" || command == "G18" || command == "G19") { plane_ = command[2] - '7'; return; }
    if (command == "G0" || command == "G1" || command == "G00" || command == "G01") return linear_move(words, line_number);
    if (command == "G2" || command == "G3" || command == "G02" || command == "G03") return arc_move(words, line_number);
    if (command == "G4" || command == "G04") return dwell(words, line_number);
    if (command == "G90") { absolute_xyz_ = true; absolute_e_ = true; return; }  // RepRap: G90 also sets E absolute
    if (command == "G91") { absolute_xyz_ = false; absolute_e_ = false; return; }
    if (command == "M82") { absolute_e_ = true; return; }
    if (command == "M83") { absolute_e_ = false; return; }
    if (command == "M404") return;  // the filament's diameter: read before the moves (read_slicer_settings)
    // Marlin's and RepRapFirmware's speed and flow overrides, S in percent (without S they only report).
    if (command == "M220" || command == "M221") {
      if (!words['S']) return;
      const double percent = number(words, 'S', line_number);
      if (!(percent > 0 && percent <= 1000))
        fail(line_number, fmt::format("{} S{}: the {} factor must be in (0, 1000] %", command, percent, command == "M220" ? "speed" : "flow"));
      (command == "M220" ? file_speed_factor_ : file_flow_factor_) = percent / 100;
      return;
    }
    if (command == "G20") { unit_to_mm_ = 25.4; return; }
    if (command == "G21") { unit_to_mm_ = 1.0; return; }
    if (command == "G92") {
      for (int axis = 0; axis < 3; ++axis)
        if (words["XYZ"[axis]]) position_[axis] = number(words, "XYZ"[axis], line_number) * unit_to_mm_;
      if (words[extrusion_axis_]) e_ = number(words, extrusion_axis_, line_number) * unit_to_mm_;
      if (!words['X'] && !words['Y'] && !words['Z'] && !words[extrusion_axis_]) { position_ = {0, 0, 0}; e_ = 0; }
      return;
    }
  }

  /// Axes a move may name that this reader does not follow: rotary A B C, secondary U V W, and E
  /// where the slicer put the extrusion on another axis. Ignoring one would print the wrong thing.
  void check_axes(const Words& words, int line_number) const {
    for (const char axis : std::string_view("ABCUVWE")) {
      if (axis == extrusion_axis_ || !words[axis]) continue;
      if (axis == 'E')
        fail(line_number, fmt::format("{} moves E, but the file's slicer settings put the extrusion on {} (extrusion_axis = {})",
                                      words.command, extrusion_axis_, extrusion_axis_));
      fail(line_number, fmt::format("{} moves the {} axis, which this reader does not follow; if the file extrudes on {} (Slic3r's "
                                    "mach3 or machinekit flavour), it needs its slicer settings at the end (; extrusion_axis = {})",
                                    words.command, axis, axis, axis));
    }
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
    check_axes(words, line_number);
    if (!words[extrusion_axis_]) return e_;
    const double value = number(words, extrusion_axis_, line_number) * unit_to_mm_;
    return absolute_e_ ? value : e_ + value;
  }
  void update_feed_rate(const Words& words, int line_number) {
    if (!words['F']) return;
    const double feed = number(words, 'F', line_number) * unit_to_mm_;
    if (!(feed > 0)) fail(line_number, fmt::format("F{} : the feed rate must be > 0 (mm/min)", feed));
    const double mm_to_world = settings_.length_scale * settings_.geometry_scale;  // m per G-code mm
    if (feed / 60 * mm_to_world > kMaxFeedSpeed * (1 + 1e-6))  // the scale is a float: 10 m/s itself is taken
      fail(line_number, fmt::format("F{:g}: a feed rate of {:.3g} m/s, beyond any printer; the fastest this reader takes is F{:.6g} "
                                    "({} m/s at this file's scale{})",
                                    feed / unit_to_mm_, feed / 60 * mm_to_world, kMaxFeedSpeed / mm_to_world * 60 / unit_to_mm_,
                                    kMaxFeedSpeed, settings_.geometry_scale != 1 ? fmt::format(", × {:g}", double(settings_.geometry_scale)) : ""));
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
    const double mm3 = volumetric_ ? extrusion_mm : extrusion_mm * kPiDouble * filament_diameter_mm_ * filament_diameter_mm_ / 4;
    return mm3 * 1e-9 * std::pow(static_cast<double>(settings_.geometry_scale), 3);  // m³
  }

  /// E units of material a move lays out of its `extrusion`: retracted filament is pushed back
  /// first; what an E-only move (`moving` false) pushes beyond that (a restart's extra length, a
  /// prime) comes out with the next extruding move, where the slicers count it too.
  double laid_by(double extrusion, bool moving) {
    if (extrusion < 0) {
      retracted_ -= extrusion;
      return 0;
    }
    const double refill = std::min(extrusion, retracted_);
    retracted_ -= refill;
    primed_ += extrusion - refill;
    if (!moving || primed_ == 0) return 0;
    return std::exchange(primed_, 0.0);
  }

  /// Adds one straight piece from position_ to `target` with `extrusion` E units.
  /// The file would make more moves than GcodeSettings::max_moves allows.
  [[noreturn]] void fail_move_count(int line_number, double adding) const {
    fail(line_number, fmt::format("the path would be more than {} moves here ({} so far, {:.3g} more on this line; arcs are split "
                                  "into {} m lines): too large to hold in memory",
                                  settings_.max_moves, program_.moves.size(), adding, settings_.arc_segment_length));
  }

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
    move.duration = travel_mm / (feed_rate_ * settings_.speed_scale * file_speed_factor_) * 60;
    move.dwell = length_mm == 0;
    move.material_volume = volume_of(laid_by(extrusion, length_mm > 0)) * settings_.flow_scale * file_flow_factor_;
    if (diameter_assumed_ && move.material_volume > 0) {
      diameter_assumed_ = false;  // said once, at the first move that lays material
      program_.warnings.push_back(Diagnostic{
          SourceLocation{file_.string(), line_number},
          fmt::format("E counts millimetres of filament, but neither the file nor the scene says how thick: read as {} mm "
                      "filament; sliced for {} mm filament, the print would need {:.3g} times this material. Set <filament_diameter> "
                      "in the scene's <gcode> to say which",
                      kAssumedFilamentMm, kOtherFilamentMm, std::pow(kOtherFilamentMm / kAssumedFilamentMm, 2))});
    }
    program_.net_extrusion += extrusion;
    program_.material_volume += move.material_volume;
    program_.duration += move.duration;
    if (move.duration > 0) {
      if (program_.moves.size() >= settings_.max_moves) fail_move_count(line_number, 1);
      program_.moves.push_back(std::move(move));
    }
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
    // The arc's plane (G17 XY, G18 ZX, G19 YZ): its two axes in the order that makes the third the
    // normal (right-handed), the centre's offset letters, and the axis moved linearly (a helix).
    static constexpr std::array<std::array<int, 3>, 3> kPlaneAxes{{{0, 1, 2}, {2, 0, 1}, {1, 2, 0}}};
    static constexpr std::array<std::array<char, 2>, 3> kOffsetLetters{{{'I', 'J'}, {'K', 'I'}, {'J', 'K'}}};
    const auto [u, v, normal] = kPlaneAxes[plane_];
    const auto [u_letter, v_letter] = kOffsetLetters[plane_];
    const double su = position_[u], sv = position_[v];
    double cu = 0, cv = 0;
    if (words[u_letter] || words[v_letter]) {
      cu = su + number(words, u_letter, line_number) * unit_to_mm_;
      cv = sv + number(words, v_letter, line_number) * unit_to_mm_;
    } else if (words['R']) {
      // Centre from the radius: on the chord's bisector; R < 0 picks the larger arc.
      const double radius = number(words, 'R', line_number) * unit_to_mm_;
      const double du = target[u] - su, dv = target[v] - sv, chord = std::hypot(du, dv);
      if (chord == 0 || std::abs(radius) < chord / 2)
        fail(line_number, fmt::format("{} R{}: the radius is shorter than half the chord ({} mm)", words.command, radius, chord / 2));
      const double offset = std::sqrt(radius * radius - chord * chord / 4) * ((clockwise == (radius > 0)) ? -1 : 1);
      cu = su + du / 2 - offset * dv / chord;
      cv = sv + dv / 2 + offset * du / chord;
    } else {
      fail(line_number, fmt::format("{} needs a centre ({} and {}) or a radius (R)", words.command, u_letter, v_letter));
    }
    const double radius = std::hypot(su - cu, sv - cv);
    const double end_radius = std::hypot(target[u] - cu, target[v] - cv);
    if (radius == 0 || std::abs(end_radius - radius) > 0.01 * radius + 0.02)
      fail(line_number, fmt::format("{}: start and end are not on one circle around ({}, {}) (radii {} and {} mm)", words.command,
                                    cu, cv, radius, end_radius));
    const double start_angle = std::atan2(sv - cv, su - cu);
    double sweep = std::atan2(target[v] - cv, target[u] - cu) - start_angle;
    if (clockwise && sweep >= 0) sweep -= 2 * kPiDouble;
    if (!clockwise && sweep <= 0) sweep += 2 * kPiDouble;
    const double arc_mm = std::abs(sweep) * radius;
    const double chords = std::ceil(arc_mm * settings_.length_scale * settings_.geometry_scale / settings_.arc_segment_length);
    if (!(chords <= kMaxArcPieces))
      fail(line_number, fmt::format("{}: an arc of {:.4g} mm (radius {:.4g} mm) would be {:.3g} lines of {} m; is its centre right?",
                                    words.command, arc_mm, radius, chords, settings_.arc_segment_length));
    if (chords > double(settings_.max_moves - std::min(settings_.max_moves, program_.moves.size())))
      fail_move_count(line_number, chords);
    const int pieces = std::max(1, static_cast<int>(chords));
    const double start_normal = position_[normal], total_e = e_target_value - e_;
    for (int k = 1; k <= pieces; ++k) {
      const double fraction = double(k) / pieces;
      const double angle = start_angle + sweep * fraction;
      std::array<double, 3> point{};
      point[u] = cu + radius * std::cos(angle);
      point[v] = cv + radius * std::sin(angle);
      point[normal] = start_normal + (target[normal] - start_normal) * fraction;
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
    if (program_.moves.size() >= settings_.max_moves) fail_move_count(line_number, 1);
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
  double file_speed_factor_ = 1;              // the file's M220 S/100
  double file_flow_factor_ = 1;               // the file's M221 S/100
  double unit_to_mm_ = 1;
  bool absolute_xyz_ = true, absolute_e_ = true;
  int plane_ = 0;                    // arcs in 0: XY (G17), 1: ZX (G18), 2: YZ (G19)
  double retracted_ = 0, primed_ = 0;  // E units pulled back, and pushed out beyond that, not yet laid
  char extrusion_axis_ = 'E';        // 'A' for Slic3r's mach3 and machinekit flavours
  bool volumetric_ = false;          // E in mm³ (from the scene, else the file)
  double filament_diameter_mm_ = kAssumedFilamentMm;
  bool diameter_assumed_ = false;  // neither the file nor the scene said: warn at the first extruding move
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
  if (!(settings.length_scale > 0) || (settings.filament_diameter && !(*settings.filament_diameter > 0)) ||
      !(settings.default_feed_rate > 0) ||
      !(settings.arc_segment_length > 0) || !(settings.geometry_scale > 0) || !(settings.speed_scale > 0) || !(settings.flow_scale > 0))
    throw Error("G-code settings: length_scale, geometry_scale, filament_diameter, default_feed_rate, arc_segment_length, speed_scale "
                "and flow_scale must be > 0");
  return Parser(file, settings).parse(text);
}

GcodeProgram read_gcode(const fs::path& file, const GcodeSettings& settings) {
  return parse_gcode(read_text_file(file, "G-code file"), file, settings);
}

}  // namespace m3dp::toolpath
