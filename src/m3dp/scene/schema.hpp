#pragma once
// The scene language's schema (issue 42): the quantities and units a value may be written in, the
// ranges it may take, and the table of the plugin's elements that the reader walks, the reference
// page (`m3dp schema`, docs/scene_reference.md) is made of, and a test gives each a bad value. A row
// is an element's block, name, kind, unit family, range, whether it is required, a line of doc, the
// engine's name for it where that differs, and how it fills a Scene; its default is read from a
// default Scene (the settings structs), never written twice. Elements whose meaning is special
// (boxes, vectors, names of other things) have rows without a setter: documented and checked as
// children here, read by hand by the reader's element files (scene_reader.hpp lists them).
#include <functional>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <variant>
#include <vector>

namespace m3dp::material {
struct Material;
struct Rheology;
}  // namespace m3dp::material
namespace m3dp::sensors {
struct CameraSettings;
}

namespace m3dp::scene {

struct Scene;
struct PrintHead;
struct FluidBlock;
struct NozzleMount;
struct MobileBase;

/// What a block's rows fill: the scene, or the one thing in it the block describes (a material, a
/// rheology, a print head, a camera, a fluid block, a nozzle mount, a mobile base).
using SchemaTarget = std::variant<Scene*, material::Material*, material::Rheology*, PrintHead*, sensors::CameraSettings*, FluidBlock*,
                                  NozzleMount*, MobileBase*>;

// ---- units: every numeric element may say unit="..."; values are stored in SI ----
inline constexpr double kRadiansPerDegree = 3.14159265358979323846 / 180;
enum class Quantity {
  plain_number, length, time, speed, acceleration, density, dynamic_viscosity, fraction, angle, mass, stress, stress_rate, rate,
  consistency, surface_tension, stiffness, area
};

struct Unit {
  std::string_view symbol;
  double to_si;  // SI value = written value × to_si
};

struct QuantityInfo {
  std::string_view name;       // "length", for messages
  std::string_view si_symbol;  // shown with limits; empty for plain numbers and fractions
  std::span<const Unit> units;
};
[[nodiscard]] QuantityInfo quantity_info(Quantity quantity);

/// The magnitudes a quantity may have in a scene: physical bounds, well inside what the engine's
/// float stores finite and non-zero (about 1e-38 to 3e38). A value below `smallest` (other than 0)
/// or beyond `largest` is an error at its line: checked in double, a 1e308 density would have run as
/// inf, a 1e-300 radius as 0.
struct Magnitude {
  double smallest, largest;
};
[[nodiscard]] Magnitude magnitude(Quantity quantity);

/// The range a value may take (SI), with the words that explain it.
struct Limits {
  std::optional<double> greater_than;
  std::optional<double> at_least;
  std::optional<double> at_most;
  std::optional<double> less_than;

  static Limits any() { return {}; }
  static Limits positive() { return {0.0, std::nullopt, std::nullopt, std::nullopt}; }
  static Limits non_negative() { return {std::nullopt, 0.0, std::nullopt, std::nullopt}; }
  static Limits positive_up_to(double maximum) { return {0.0, std::nullopt, maximum, std::nullopt}; }
  static Limits between(double low, double high) { return {std::nullopt, low, high, std::nullopt}; }

  [[nodiscard]] bool admits(double value) const {
    return (!greater_than || value > *greater_than) && (!at_least || value >= *at_least) && (!at_most || value <= *at_most) &&
           (!less_than || value < *less_than);
  }
  /// "> 0 s", "in [0, 1)", "any number".
  [[nodiscard]] std::string describe(std::string_view unit) const;
};

// ---- the table: the SDF elements M3DP reads, then its plugin's ----
enum class ValueKind {
  number,    // a real number in the row's quantity (unit="..." converts), within its limits
  integer,   // a whole number within its limits
  boolean,   // true or false (1 or 0)
  keyword,   // one of the row's words
  structure  // anything else (a box, a vector, a name): read by hand, in the table for its doc and as a known child
};

struct SchemaRow {
  std::string_view block;     // the block it sits in (schema_blocks): "solver", "camera", "rheology bingham"
  std::string_view name;      // the element's name as written
  ValueKind kind = ValueKind::number;
  Quantity quantity = Quantity::plain_number;
  Limits limits;
  bool required = false;
  bool repeated = false;      // may be written more than once (a structure read by hand)
  bool ignored = false;       // valid SDF that M3DP accepts and does not use (the SDF blocks' other children)
  std::string_view doc;       // one line: what it is, and what 0 means where that is special
  std::string_view field;     // the engine's name of what it fills, where that differs from `name`
  std::vector<std::string_view> words;  // a keyword's words; `set` gets the word's index
  std::string_view hint;      // a keyword's words explained, for its error message
  /// Fills the block's target from a valid value (SI for numbers, 0/1 for booleans, the word's index
  /// for keywords); null for structure rows.
  std::function<void(const SchemaTarget&, double)> set;
  /// The value in a target, as the reference writes it (the default from a default target); null: none.
  std::function<std::string(const SchemaTarget&)> show;
};

/// Every row, block by block in the reference's order.
[[nodiscard]] std::span<const SchemaRow> schema_rows();
/// The row `name` of `block` (one the code knows is there).
[[nodiscard]] const SchemaRow& schema_row(std::string_view block, std::string_view name);
/// The rows of one block, in order.
[[nodiscard]] std::vector<const SchemaRow*> schema_block(std::string_view block);
/// The blocks the table has, in order, with a line about each.
struct SchemaBlock {
  std::string_view name;    // "solver"
  std::string_view path;    // where it is written: "<plugin><solver>"
  std::string_view doc;
  std::string_view parent;  // the block it sits in: "plugin", or "material" for a material's parts
  /// A default target of the block's kind (a default Scene, material, camera...): what the reference
  /// shows as each row's default.
  SchemaTarget (*defaults)();
};
[[nodiscard]] std::span<const SchemaBlock> schema_blocks();

/// The reference page (Markdown) of everything in the table: what `m3dp schema` prints and
/// docs/scene_reference.md holds.
[[nodiscard]] std::string schema_reference();

}  // namespace m3dp::scene
