// SPDX-License-Identifier: MIT
// The only translation unit that includes OpenVDB (its headers are slow to compile).
#include "solver/material_io.h"

#include <algorithm>
#include <cctype>
#include <openvdb/openvdb.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fmt/format.h>
#include <fstream>
#include <mutex>
#include <set>

#include "solver/atomic_file.h"
#include "solver/child_process.h"
#include "solver/memory.h"
#include "solver/status.h"

namespace translume {
namespace {

constexpr const char* kFormat = "material/1";

// Integrity trailer (docs/formats.md): WriteMaterial appends 24 bytes after OpenVDB's file,
// which OpenVDB never reads (it seeks to its grids by offset): "TLSUM001", the length of the
// file before the trailer and its 64-bit FNV-1a hash, both little-endian. The file metadata
// `translume_checksum` says that the file had one, so a file cut short is caught too.
constexpr char kTrailerMagic[8] = {'T', 'L', 'S', 'U', 'M', '0', '0', '1'};
constexpr int kTrailerBytes = 24;
constexpr const char* kChecksumKind = "fnv1a64-trailer";

// FNV-1a over the first `bytes` bytes of `in` from its current position (bytes 0..).
uint64_t Fnv1a64(std::istream& in, uint64_t bytes) {
  uint64_t h = 14695981039346656037ull;
  std::vector<char> buf(1 << 20);
  while (bytes > 0) {
    const std::streamsize n = std::streamsize(std::min<uint64_t>(bytes, buf.size()));
    if (!in.read(buf.data(), n)) return ~h;  // short: cannot match
    for (std::streamsize i = 0; i < n; ++i) h = (h ^ uint64_t(uint8_t(buf[size_t(i)]))) * 1099511628211ull;
    bytes -= uint64_t(n);
  }
  return h;
}

void PutU64(char* out, uint64_t v) {
  for (int b = 0; b < 8; ++b) out[b] = char((v >> (8 * b)) & 0xff);
}

uint64_t GetU64(const char* in) {
  uint64_t v = 0;
  for (int b = 0; b < 8; ++b) v |= uint64_t(uint8_t(in[b])) << (8 * b);
  return v;
}

void AppendTrailer(const std::string& path) {
  const uint64_t size = std::filesystem::file_size(path);
  std::ifstream in(path, std::ios::binary);
  const uint64_t hash = Fnv1a64(in, size);
  char trailer[kTrailerBytes];
  std::copy(kTrailerMagic, kTrailerMagic + 8, trailer);
  PutU64(trailer + 8, size);
  PutU64(trailer + 16, hash);
  std::ofstream out(path, std::ios::binary | std::ios::app);
  out.write(trailer, kTrailerBytes);
  if (!out) throw InputError(fmt::format("{}: cannot write", path));
}

// Whether `path` ends in an integrity trailer; throws InputError where it does but the file
// does not match it.
bool CheckTrailer(const std::string& path, uint64_t size) {
  std::ifstream in(path, std::ios::binary);
  char trailer[kTrailerBytes];
  in.seekg(std::streamoff(size - kTrailerBytes));
  if (!in.read(trailer, kTrailerBytes) || !std::equal(kTrailerMagic, kTrailerMagic + 8, trailer)) return false;
  const uint64_t length = GetU64(trailer + 8);
  if (length != size - kTrailerBytes)
    throw InputError(fmt::format("{}: corrupt material file: {} bytes where its checksum trailer says {}",
                                 path, size - kTrailerBytes, length));
  in.seekg(0);
  if (Fnv1a64(in, length) != GetU64(trailer + 16))
    throw InputError(fmt::format("{}: corrupt material file: its contents do not match their checksum "
                                 "(damaged after it was written)", path));
  return true;
}

// OpenVDB trusts the lengths in a file's header and allocates them before reading: a damaged
// file without a trailer (another tool's) made it allocate 5-22 GB. "" if the header's counts,
// string lengths and grid offsets (docs/formats.md) fit in the file, else the problem. Checks
// files of format versions 218 (string UUIDs) to OPENVDB_FILE_VERSION; older ones as they are.
std::string VdbHeaderProblem(const std::string& path, uint64_t size) {
  std::ifstream in(path, std::ios::binary);
  uint64_t pos = 0;
  bool cut = false;
  const auto read = [&](void* out, uint64_t n) {
    if (cut || n > size - pos || !in.read(static_cast<char*>(out), std::streamsize(n))) cut = true;
    else pos += n;
  };
  const auto u32 = [&] {
    uint8_t b[4] = {0, 0, 0, 0};
    read(b, 4);
    return uint32_t(b[0]) | uint32_t(b[1]) << 8 | uint32_t(b[2]) << 16 | uint32_t(b[3]) << 24;
  };
  const auto u64 = [&] { const uint64_t lo = u32(); return lo | uint64_t(u32()) << 32; };
  // A length-prefixed string: its length must fit in the rest of the file.
  const auto skip_string = [&](const char* what) -> std::string {
    const uint32_t n = u32();
    if (cut) return "";
    if (n > size - pos) return fmt::format("{} of {} bytes, beyond the file's end", what, n);
    in.seekg(std::streamoff(n), std::ios::cur);
    pos += n;
    return "";
  };
  if (u64() != 0x56444220) return "not an OpenVDB file (no magic number)";
  const uint32_t version = u32();
  if (version < openvdb::OPENVDB_FILE_VERSION_ROOTNODE_MAP || version > openvdb::OPENVDB_FILE_VERSION)
    return fmt::format("OpenVDB file format version {}, this build reads {} to {}", version,
                       int(openvdb::OPENVDB_FILE_VERSION_ROOTNODE_MAP), openvdb::OPENVDB_FILE_VERSION);
  if (version < openvdb::OPENVDB_FILE_VERSION_BOOST_UUID) return "";
  u32(), u32();  // library major, minor
  char offsets = 0, uuid[36];
  read(&offsets, 1);
  read(uuid, 36);
  const uint32_t entries = u32();
  if (!cut && entries > size - pos) return fmt::format("{} metadata entries, more than the file holds", entries);
  for (uint32_t e = 0; e < entries && !cut; ++e)
    for (const char* what : {"a metadata name", "a metadata type", "a metadata value"})
      if (std::string p = skip_string(what); !p.empty()) return p;
  const uint32_t grids = u32();
  if (!cut && grids > size - pos) return fmt::format("{} grids, more than the file holds", grids);
  for (uint32_t g = 0; g < grids && offsets && !cut; ++g) {
    for (const char* what : {"a grid name", "a grid type", "a grid's instance parent"})
      if (std::string p = skip_string(what); !p.empty()) return p;
    const uint64_t grid_pos = u64(), block_pos = u64(), end_pos = u64();
    if (cut) break;
    if (!(pos <= grid_pos && grid_pos <= block_pos && block_pos <= end_pos))
      return fmt::format("grid {}'s offsets {}, {}, {} are out of order", g, grid_pos, block_pos, end_pos);
    if (end_pos > size)
      return fmt::format("grid {} ends at byte {}, beyond the file's {} bytes (truncated?)", g, end_pos, size);
    in.seekg(std::streamoff(end_pos));
    pos = end_pos;
  }
  return cut ? "its header ends early (truncated?)" : "";
}

void InitVdb() {
  static std::once_flag once;
  std::call_once(once, [] { openvdb::initialize(); });
}

template <typename GridT>
typename GridT::Ptr MakeGrid(const std::string& name, double h) {
  auto grid = GridT::create();
  grid->setName(name);
  grid->setTransform(openvdb::math::Transform::createLinearTransform(h));
  return grid;
}

}  // namespace

namespace {

void WriteVdb(const std::string& path, const Material& m, const MaterialCorruption* corrupt) {
  InitVdb();
  const double h = m.spacing_mm;
  auto kappa = MakeGrid<openvdb::Vec3fGrid>("kappa", h);
  auto mu = MakeGrid<openvdb::Vec3fGrid>("mu", h);
  auto albedo = MakeGrid<openvdb::Vec3fGrid>("albedo", h);
  auto density = MakeGrid<openvdb::FloatGrid>("density", h);
  density->setGridClass(openvdb::GRID_FOG_VOLUME);
  auto ak = kappa->getAccessor();
  auto am = mu->getAccessor();
  auto aa = albedo->getAccessor();
  auto ad = density->getAccessor();
  const GridShape& s = m.shape;
  for (int64_t k = 0; k < s.nz; ++k)
    for (int64_t j = 0; j < s.ny; ++j)
      for (int64_t i = 0; i < s.nx; ++i) {
        const int64_t p = s.index(i, j, k);
        const openvdb::Coord xyz{int32_t(i), int32_t(j), int32_t(k)};
        openvdb::Vec3f kv(m.kappa[0][p], m.kappa[1][p], m.kappa[2][p]);
        openvdb::Vec3f mv(m.mu[0][p], m.mu[1][p], m.mu[2][p]);
        ak.setValue(xyz, kv);
        am.setValue(xyz, mv);
        float sigma = 0;
        openvdb::Vec3f alb;
        for (int c = 0; c < 3; ++c) {
          sigma += 1.0f / (3.0f * kv[c]) / 3.0f;
          alb[c] = 1.0f - 3.0f * kv[c] * mv[c];
        }
        aa.setValue(xyz, alb);
        ad.setValue(xyz, sigma);
      }
  openvdb::GridPtrVec grids{kappa, mu, density, albedo};
  openvdb::MetaMap meta;
  using MC = MaterialCorruption;
  const MC bad = corrupt ? *corrupt : MC(-1);
  if (bad != MC::kMissingC) meta.insertMeta("C", openvdb::FloatMetadata(float(m.C)));
  meta.insertMeta("eta", openvdb::FloatMetadata(float(m.eta)));
  meta.insertMeta("translume_format",
                  openvdb::StringMetadata(bad == MC::kWrongFormat ? "material/99" : kFormat));
  if (bad != MC::kNoChecksum) meta.insertMeta("translume_checksum", openvdb::StringMetadata(kChecksumKind));
  if (bad == MC::kUnknownMetadata) meta.insertMeta("albedo_scale", openvdb::FloatMetadata(2.0f));
  if (bad == MC::kMissingMu) grids = {kappa, density, albedo};
  if (bad == MC::kShapeMismatch) {
    for (int32_t j = 0; j < int32_t(s.ny); ++j)
      for (int32_t i = 0; i < int32_t(s.nx); ++i) am.setValueOff(openvdb::Coord{i, j, int32_t(s.nz - 1)});
  }
  if (bad == MC::kMissingVoxel) {
    am.setValueOff(openvdb::Coord(1, 1, 1));
    ak.setValueOff(openvdb::Coord(1, 1, 1));
  }
  if (bad == MC::kNegativeKappa) ak.setValue(openvdb::Coord(1, 0, 0), openvdb::Vec3f(0.1f, -0.2f, 0.1f));
  if (bad == MC::kNanMu) am.setValue(openvdb::Coord(0, 1, 0), openvdb::Vec3f(0.01f, 0.01f, NAN));
  if (bad == MC::kWrongGridType) {
    auto fake = MakeGrid<openvdb::FloatGrid>("mu", m.spacing_mm);
    fake->tree().setValue(openvdb::Coord(0, 0, 0), 1.0f);
    grids = {kappa, fake, density, albedo};
  }
  if (bad == MC::kHugeTiles)
    for (auto* grid : {kappa.get(), mu.get()})
      grid->fill(openvdb::CoordBBox(openvdb::Coord(0), openvdb::Coord(4095)), openvdb::Vec3f(0.5f), true);
  if (bad == MC::kRotated || bad == MC::kMirrored)
    for (const auto& grid : grids) {
      if (bad == MC::kRotated) grid->transform().postRotate(0.3, openvdb::math::Z_AXIS);
      else grid->transform().postScale(openvdb::Vec3d(1, -1, 1));
    }
  WriteAtomically(path, [&](const std::string& tmp) {
    try {
      openvdb::io::File file(tmp);
      file.write(grids, meta);
      file.close();
    } catch (const openvdb::Exception& e) {
      throw InputError(fmt::format("{}: cannot write material file: {}", path, e.what()));
    }
    if (bad != MC::kNoChecksum) AppendTrailer(tmp);
  });
}

}  // namespace

void WriteMaterial(const std::string& path, const Material& m) {
  if (std::string err = m.Validate(); !err.empty()) {
    throw InputError(fmt::format("{}: refusing to write an invalid material: {}", path, err));
  }
  WriteVdb(path, m, nullptr);
}

void WriteCorruptMaterialForTest(const std::string& path, const Material& m,
                                 MaterialCorruption corruption) {
  WriteVdb(path, m, &corruption);
}

namespace {

// At most 80 characters of `text` for an error line, non-printable ones as '?', runs of blanks
// as one (a corrupt file's "names" can be megabytes of garbage).
std::string Short(const std::string& text) {
  std::string out;
  for (char c : text) {
    if (out.size() >= 80) return out + "...";
    const char p = std::isprint(static_cast<unsigned char>(c)) ? c : '?';
    if (p == ' ' && !out.empty() && out.back() == ' ') continue;
    out += p;
  }
  return out;
}

// Reads the material of an OpenVDB file; `trailer` says whether its checksum trailer was found
// and checked. Uses no thread pool, so that it can run in RunInChildProcess's child: the
// active boxes and counts are summed serially (OpenVDB's own use TBB), and where `keep_grids`
// is given the grids are moved there instead of freed (freeing a tree uses TBB too).
Material ReadMaterialFile(const std::string& path, bool trailer,
                          std::vector<openvdb::GridBase::Ptr>* keep_grids) {
  openvdb::io::File file(path);
  // Without delayed loading: the whole file is read now, as it is used, and damaged files crash
  // OpenVDB's delayed-load bookkeeping (an assertion on its masks) 3x as often.
  file.open(false);
  Material m;
  auto meta = file.getMetadata();
  bool have_c = false, have_eta = false;
  const std::set<std::string> known = {"C", "eta", "translume_format", "translume_checksum"};
  for (auto it = meta->beginMeta(); it != meta->endMeta(); ++it) {
    const std::string& key = it->first;
    if (!known.count(key)) {
      throw InputError(fmt::format("{}: unknown file metadata '{}' (expected C, eta, "
                                   "translume_format, translume_checksum)", path, Short(key)));
    }
    if (key == "translume_checksum") {
      // Written with an integrity trailer (checked before OpenVDB read the file): without it
      // the file was cut short.
      if (!trailer)
        throw InputError(fmt::format("{}: corrupt material file: its checksum trailer is missing (cut short?)", path));
      continue;
    }
    if (key == "translume_format") {
      const std::string v = it->second->str();
      if (v != kFormat)
        throw InputError(fmt::format("{}: translume_format is '{}', this build reads '{}'", path,
                                     Short(v), kFormat));
      continue;
    }
    double value = 0;
    if (auto f = openvdb::DynamicPtrCast<openvdb::FloatMetadata>(it->second)) value = f->value();
    else if (auto d = openvdb::DynamicPtrCast<openvdb::DoubleMetadata>(it->second)) value = d->value();
    else
      throw InputError(fmt::format("{}: metadata '{}' has type {}, expected float", path, key,
                                   it->second->typeName()));
    if (key == "C") { m.C = value; have_c = true; }
    if (key == "eta") { m.eta = value; have_eta = true; }
  }
  if (!have_c) throw InputError(fmt::format("{}: missing file metadata 'C'", path));
  if (!have_eta) throw InputError(fmt::format("{}: missing file metadata 'eta'", path));
  if (!(m.C >= 1) || !std::isfinite(m.C))
    throw InputError(fmt::format("{}: metadata C = {} is not a finite number >= 1", path, m.C));
  if (!(m.eta > 0) || !std::isfinite(m.eta))
    throw InputError(fmt::format("{}: metadata eta = {} is not positive", path, m.eta));

  openvdb::Vec3fGrid::Ptr grids[2];
  const char* names[2] = {"kappa", "mu"};
  for (int g = 0; g < 2; ++g) {
    if (!file.hasGrid(names[g]))
      throw InputError(fmt::format("{}: missing grid '{}'", path, names[g]));
    auto base = file.readGrid(names[g]);
    if (keep_grids) keep_grids->push_back(base);
    grids[g] = openvdb::gridPtrCast<openvdb::Vec3fGrid>(base);
    if (!grids[g])
      throw InputError(fmt::format("{}: grid '{}' has type {}, expected Vec3f", path, names[g],
                                   base->valueType()));
  }
  file.close();

  openvdb::CoordBBox box[2];
  openvdb::Index64 active_voxels[2] = {0, 0};
  for (int g = 0; g < 2; ++g) {
    const auto& xf = grids[g]->transform();
    const openvdb::Vec3d vs = xf.voxelSize();
    const openvdb::Vec3d origin = xf.indexToWorld(openvdb::Vec3d(0, 0, 0));
    // Index axis a must map to world axis a, scaled by h: no rotation, no mirror.
    bool axis_aligned = xf.isLinear();
    for (int a = 0; a < 3 && axis_aligned; ++a) {
      openvdb::Vec3d unit(0, 0, 0);
      unit[a] = 1;
      openvdb::Vec3d expected(0, 0, 0);
      expected[a] = vs[0];
      axis_aligned = ((xf.indexToWorld(unit) - origin) - expected).length() <= 1e-6 * vs[0];
    }
    if (!axis_aligned || origin.length() > 1e-6 * vs[0])
      throw InputError(fmt::format("{}: grid '{}' does not have a uniform, axis-aligned linear transform "
                                   "with voxel (0,0,0) at the origin (rotated, mirrored or shifted grids "
                                   "are not read)", path, names[g]));
    if (g == 0) m.spacing_mm = vs[0];
    else if (std::abs(vs[0] - m.spacing_mm) > 1e-6 * m.spacing_mm)
      throw InputError(fmt::format("{}: grids 'kappa' and 'mu' have different voxel sizes "
                                   "({} and {} mm)", path, m.spacing_mm, vs[0]));
    openvdb::Index64 active = 0;
    for (auto it = grids[g]->cbeginValueOn(); it; ++it) {
      openvdb::CoordBBox b;
      it.getBoundingBox(b);
      box[g].expand(b);
      active += it.getVoxelCount();
    }
    active_voxels[g] = active;
    if (box[g].empty()) throw InputError(fmt::format("{}: grid '{}' is empty", path, names[g]));
    if (box[g].min() != openvdb::Coord(0, 0, 0))
      throw InputError(fmt::format("{}: grid '{}' does not start at voxel (0,0,0)", path,
                                   names[g]));
  }
  if (box[0] != box[1])
    throw InputError(fmt::format("{}: grids 'kappa' and 'mu' have different shapes", path));
  const openvdb::Coord dim = box[0].dim();
  m.shape = {dim.x(), dim.y(), dim.z()};
  for (int g = 0; g < 2; ++g) {
    if (int64_t(active_voxels[g]) != m.shape.size())
      throw InputError(fmt::format("{}: grid '{}' has {} active voxels, a dense {} grid needs {}",
                                   path, names[g], active_voxels[g],
                                   m.shape.ToString(), m.shape.size()));
  }
  // A valid file of tiles can hold a grid far too large to hold densely (4096^3 in 480 KB).
  CheckFitsInMemory(m.shape.size() * 6 * int64_t(sizeof(float)),
                    fmt::format("{}: its {} grid, held densely,", path, m.shape.ToString()));
  for (int c = 0; c < 3; ++c) {
    m.kappa[c].resize(m.shape.size());
    m.mu[c].resize(m.shape.size());
  }
  auto ak = grids[0]->getConstAccessor();
  auto am = grids[1]->getConstAccessor();
  const GridShape& s = m.shape;
  for (int64_t k = 0; k < s.nz; ++k)
    for (int64_t j = 0; j < s.ny; ++j)
      for (int64_t i = 0; i < s.nx; ++i) {
        const openvdb::Coord xyz{int32_t(i), int32_t(j), int32_t(k)};
        const openvdb::Vec3f kv = ak.getValue(xyz), mv = am.getValue(xyz);
        const int64_t p = s.index(i, j, k);
        for (int c = 0; c < 3; ++c) {
          m.kappa[c][p] = kv[c];
          m.mu[c][p] = mv[c];
        }
      }
  if (std::string err = m.Validate(); !err.empty())
    throw InputError(fmt::format("{}: {}", path, err));
  return m;
}

// The material as bytes, for RunInChildProcess: shape, spacing, eta, C, then kappa and mu per
// channel.
std::string EncodeMaterial(const Material& m) {
  std::string out;
  auto put = [&](const void* data, size_t bytes) { out.append(static_cast<const char*>(data), bytes); };
  const int64_t shape[3] = {m.shape.nx, m.shape.ny, m.shape.nz};
  const double scalars[3] = {m.spacing_mm, m.eta, m.C};
  put(shape, sizeof shape);
  put(scalars, sizeof scalars);
  for (const auto* field : {&m.kappa, &m.mu})
    for (const std::vector<float>& channel : *field) put(channel.data(), channel.size() * sizeof(float));
  return out;
}

Material DecodeMaterial(const std::string& bytes) {
  Material m;
  size_t at = 0;
  auto get = [&](void* data, size_t size) {
    TL_CHECK(at + size <= bytes.size());
    std::memcpy(data, bytes.data() + at, size);
    at += size;
  };
  int64_t shape[3];
  double scalars[3];
  get(shape, sizeof shape);
  get(scalars, sizeof scalars);
  m.shape = {shape[0], shape[1], shape[2]};
  m.spacing_mm = scalars[0];
  m.eta = scalars[1];
  m.C = scalars[2];
  for (auto* field : {&m.kappa, &m.mu})
    for (std::vector<float>& channel : *field) {
      channel.resize(m.shape.size());
      get(channel.data(), channel.size() * sizeof(float));
    }
  TL_CHECK(at == bytes.size());
  return m;
}

}  // namespace

Material ReadMaterial(const std::string& path) {
  InitVdb();
  namespace fs = std::filesystem;
  if (!fs::exists(path)) throw InputError(fmt::format("{}: no such file", path));
  if (fs::is_directory(path)) throw InputError(fmt::format("{}: is a folder, not a material file", path));
  // OpenVDB trusts the lengths in a file's header: cut inside it, a file can make it allocate
  // gigabytes. Every material file is tens of kilobytes at least (two grids and their trees).
  std::error_code ec;
  const auto bytes = fs::file_size(path, ec);
  if (!ec && bytes < 4096)
    throw InputError(fmt::format("{}: not a material file: {} bytes is too short for an OpenVDB file "
                                 "with two grids (truncated?)", path, bytes));
  const bool trailer = !ec && CheckTrailer(path, bytes);
  if (!trailer && !ec)
    if (const std::string problem = VdbHeaderProblem(path, bytes); !problem.empty())
      throw InputError(fmt::format("{}: not a readable OpenVDB material ({})", path, problem));
  try {
    if (trailer) return ReadMaterialFile(path, true, nullptr);
    // Another tool's file (or one written before the trailer): nothing vouches for its grid
    // data, and damaged data can make OpenVDB's reader corrupt the heap or fail an assertion.
    return DecodeMaterial(RunInChildProcess([&] {
      return EncodeMaterial(ReadMaterialFile(path, false, new std::vector<openvdb::GridBase::Ptr>));
    }));
  } catch (const InputError&) {
    throw;
  } catch (const ChildCrashed& e) {
    throw InputError(fmt::format("{}: not a readable OpenVDB material (damaged grid data: OpenVDB's "
                                 "reader {})", path, Short(e.what())));
  } catch (const std::bad_alloc&) {
    throw InputError(fmt::format("{}: not a readable OpenVDB material (damaged grid data: reading it "
                                 "asked for more memory than is available)", path));
  } catch (const std::exception& e) {
    throw InputError(fmt::format("{}: not a readable OpenVDB material (truncated or corrupt: {})", path,
                                 Short(e.what())));
  }
}

}  // namespace translume
