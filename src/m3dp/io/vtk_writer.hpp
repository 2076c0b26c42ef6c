#pragma once
// Particle frames as VTK XML UnstructuredGrid (.vtu, one vertex cell per particle; every array
// inline as base64, zlib-compressed by default) and a ParaView time-series collection (.pvd). Both
// open in ParaView as a time series. Inline base64, not appended data: see docs/architecture.md.
#include <array>
#include <cstdint>
#include <filesystem>
#include <span>
#include <string>
#include <vector>

#include "m3dp/core/state_io.hpp"
#include "m3dp/core/types.hpp"

namespace m3dp::io {

/// A named per-point array to write; `data` must stay valid during the write.
struct PointArray {
  std::string name;
  std::string vtk_type;  // "Float32", "Float64", "UInt16", "UInt64", ...
  int components = 1;
  const void* data = nullptr;
  std::size_t element_bytes = 0;  // bytes of one component

  static PointArray of(std::string name, std::span<const Real> values);
  static PointArray of(std::string name, std::span<const Vec3> values);
  static PointArray of(std::string name, std::span<const std::uint16_t> values);
  static PointArray of(std::string name, std::span<const std::uint64_t> values);
  static PointArray of(std::string name, std::span<const std::uint8_t> values);
  static PointArray of(std::string name, std::span<const std::int32_t> values);
};

/// A single number stored with the whole dataset (VTK FieldData), e.g. the particle radius.
struct FieldValue {
  std::string name;
  double value = 0;
};

/// Numbers stored with the whole dataset as one tuple, e.g. a body's position (x, y, z).
struct FieldTuple {
  std::string name;
  std::vector<double> values;
};

/// How the arrays' bytes are stored: base64 text, deflated by zlib at `zlib_level` (1 fastest,
/// 9 smallest) in blocks VTK's vtkZLibDataCompressor reads; a negative level writes base64 alone.
struct VtuEncoding {
  int zlib_level = 1;
};

/// Writes `points` and `arrays` (each with points.size() tuples) to `file`, atomically.
void write_vtu(const std::filesystem::path& file, std::span<const Vec3> points, const std::vector<PointArray>& arrays,
               const std::vector<FieldValue>& field_data = {}, const VtuEncoding& encoding = {});

/// Surfaces and lines as VTK XML PolyData (.vtp): `points`, triangles indexing them, and polylines
/// given as their points' indices (`line_points`) and where each line ends in that list
/// (`line_ends`, VTK's offsets). Point arrays have points.size() tuples.
struct PolyData {
  std::span<const Vec3> points;
  std::span<const std::array<Index, 3>> triangles;
  std::span<const Index> line_points;
  std::span<const Index> line_ends;
  std::vector<PointArray> point_arrays;
  std::vector<FieldTuple> field_data;
};

/// Writes `poly_data` to `file`, atomically, inline base64 as write_vtu.
void write_vtp(const std::filesystem::path& file, const PolyData& poly_data, const VtuEncoding& encoding = {});

/// A VTK XML MultiBlockDataSet (.vtm): one named block for each file (stored relative to the
/// .vtm's folder), in order. ParaView shows the names in its block hierarchy.
struct Block {
  std::string name;
  std::filesystem::path file;
};
void write_vtm(const std::filesystem::path& file, const std::vector<Block>& blocks);

/// A .pvd collection that is rewritten (atomically) each time a frame is added.
class PvdCollection {
 public:
  explicit PvdCollection(std::filesystem::path file) : file_(std::move(file)) {}
  /// `dataset_file` is stored relative to the .pvd's folder.
  void add(double time, const std::filesystem::path& dataset_file);
  [[nodiscard]] std::size_t size() const { return entries_.size(); }
  /// A checkpoint: its entries; load() takes them back and writes the .pvd as it was then.
  void save(StateWriter& out) const;
  void load(StateReader& in);

 private:
  void write() const;
  struct Entry {
    double time;
    std::string relative_file;
  };
  std::filesystem::path file_;
  std::vector<Entry> entries_;
};

}  // namespace m3dp::io
