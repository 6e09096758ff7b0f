// SPDX-License-Identifier: MIT
#include "solver/gl_solver.h"

#include <Eigen/Dense>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fmt/format.h>
#include <map>
#include <omp.h>
#include <sstream>

#include "solver/gl_context.h"
#include "solver/gl_internal.h"
#include "solver/gl_profile.h"
#include "solver/gl_shaders.h"
#include "solver/multigrid_hierarchy.h"
#include "solver/status.h"

namespace translume {namespace gl_internal {

// Lines of common.glsl are numbered from kCommonLine on, those of an included snippet from
// kIncludeLine on, the file's from 1 (see CompileProgram), so a log line "0:12(5): error" (Mesa)
// or "0(12) : error" (NVIDIA) can name its file: "solver/shaders/smooth.comp:12(5): error ...".
constexpr int kCommonLine = 100000;
constexpr int kIncludeLine = 200000;

std::string NameLog(const std::string& log, const std::string& common, const std::string& file,
                    const std::string& included) {
  std::istringstream in(log);
  std::string line, out;
  while (std::getline(in, line)) {
    int string_no = 0, number = 0, used = 0;
    if (std::sscanf(line.c_str(), "%d:%d%n", &string_no, &number, &used) == 2 ||
        std::sscanf(line.c_str(), "%d(%d)%n", &string_no, &number, &used) == 2) {
      const bool in_include = number >= kIncludeLine, in_common = !in_include && number >= kCommonLine;
      line = fmt::format("{}:{}{}", in_include ? included : in_common ? common : file,
                         in_include  ? number - kIncludeLine + 1
                         : in_common ? number - kCommonLine + 1
                                     : number,
                         line.substr(used));
    }
    out += line + (in.peek() == EOF ? "" : " | ");
  }
  return out;
}

const gl::EmbeddedShader& FindShader(const std::string& name);

// Replaces the line `#include "NAME"` of a shader's text (at most one) by the embedded
// solver/shaders/NAME, numbered from kIncludeLine, and sets *included to its name.
std::string SpliceInclude(const char* source, std::string* included) {
  std::string text = source;
  const std::string directive = "#include \"";
  const size_t at = text.find(directive);
  if (at == std::string::npos || (at > 0 && text[at - 1] != '\n')) return text;
  const size_t name_end = text.find('"', at + directive.size());
  const size_t line_end = text.find('\n', at);
  TL_CHECK_MSG(name_end != std::string::npos && name_end < line_end, "malformed #include");
  const int line = 1 + int(std::count(text.begin(), text.begin() + at, '\n'));
  const gl::EmbeddedShader& snippet =
      FindShader("solver/shaders/" + text.substr(at + directive.size(), name_end - at - directive.size()));
  *included = snippet.name;
  return text.substr(0, at) + fmt::format("#line {}\n{}\n#line {}\n", kIncludeLine, snippet.source, line + 1) +
         (line_end == std::string::npos ? "" : text.substr(line_end + 1));
}

// Compiles and links one compute program from the Tuning's defines (TL_IMAGES,
// TL_INVOCATION_SUMS, MG_LINE_BLOCK, TL_GROUP unless `defines` sets its own), `defines`,
// common.glsl and the file's text.
GLuint CompileProgram(const gl::EmbeddedShader& common, const std::string& defines,
                      const std::string& file_name, const char* source) {
  GLuint shader = api.CreateShader(GL_COMPUTE_SHADER);
  std::string included;
  const std::string body = SpliceInclude(source, &included);
  const std::string text =
      fmt::format("#version 430\n{}{}{}{}{}#line {}\n{}#line 1\n{}",
                  GetTuning().images ? "#define TL_IMAGES\n" : "",
                  GetTuning().invocation_sums ? "#define TL_INVOCATION_SUMS\n" : "",
                  GetTuning().line_block > 1 ? fmt::format("#define MG_LINE_BLOCK {}\n", GetTuning().line_block) : std::string(),
                  defines.find("#define TL_GROUP ") == std::string::npos
                      ? fmt::format("#define TL_GROUP {}\n", GetTuning().group)
                      : "",
                  defines, kCommonLine, common.source, body);
  const char* sources[1] = {text.c_str()};
  api.ShaderSource(shader, 1, sources, nullptr);
  api.CompileShader(shader);
  GLint ok = 0;
  api.GetShaderiv(shader, GL_COMPILE_STATUS, &ok);
  if (!ok) {
    char log[8192];
    api.GetShaderInfoLog(shader, sizeof(log), nullptr, log);
    api.DeleteShader(shader);
    throw InputError(fmt::format("--backend gl: compiling {} failed: {}", file_name,
                                 NameLog(log, common.name, file_name, included)));
  }
  GLuint program = api.CreateProgram();
  api.AttachShader(program, shader);
  api.LinkProgram(program);
  api.DeleteShader(shader);
  api.GetProgramiv(program, GL_LINK_STATUS, &ok);
  if (!ok) {
    char log[8192];
    api.GetProgramInfoLog(program, sizeof(log), nullptr, log);
    throw InputError(fmt::format("--backend gl: linking {} failed: {}", file_name, log));
  }
  return program;
}

const gl::EmbeddedShader& FindShader(const std::string& name) {
  for (int s = 0; s < gl::kNumEmbeddedShaders; ++s)
    if (name == gl::kEmbeddedShaders[s].name) return gl::kEmbeddedShaders[s];
  TL_CHECK_MSG(false, "shader " + name + " is not embedded");
  std::abort();
}

const Tuning& GetTuning() {
  static const Tuning tuning = [] {
    const char* forced = std::getenv("TRANSLUME_GL_TUNING");
    const std::string f = forced ? forced : "";
    if (!f.empty() && f != "llvmpipe" && f != "gpu")
      throw InputError(fmt::format("TRANSLUME_GL_TUNING='{}' is not llvmpipe or gpu", f));
    const bool cpu = f.empty() ? GlContext::Get().info().renderer.find("llvmpipe") != std::string::npos
                               : f == "llvmpipe";
    Tuning t;
    if (cpu) {
      t.images = true;
      t.columns = true;
      t.flat_groups = 8;
      t.group = 64;
      t.invocation_sums = true;
    }
    // One work group per field runs the tail: on llvmpipe one thread per field, so the levels
    // where the per-level dispatches' fixed cost outweighs the work; on a GPU the levels one
    // group of TL_GROUP invocations covers in a few nodes each.
    t.tail_nodes = 4096;
    t.tail_group = cpu ? 8 : 256;
    t.pack_fields = cpu ? 4 : 1;
    t.quarters = cpu;
    // On a GPU a column's serial chain of loads is the smoother's cost (docs/gpu.md); on
    // llvmpipe the invocations of a group run as SIMD lanes of one thread anyway.
    t.line_block = cpu ? 1 : 4;
    if (const char* tail = std::getenv("TRANSLUME_GL_TAIL_NODES")) t.tail_nodes = std::atoll(tail);
    if (const char* g = std::getenv("TRANSLUME_GL_TAIL_GROUP")) t.tail_group = std::atoi(g);
    if (const char* g = std::getenv("TRANSLUME_GL_GROUP")) t.group = std::max(8, std::atoi(g));
    if (const char* g = std::getenv("TRANSLUME_GL_FLAT_GROUPS")) t.flat_groups = std::max(1, std::atoi(g));
    if (const char* f = std::getenv("TRANSLUME_GL_PACK_FIELDS")) t.pack_fields = std::atoi(f) == 4 ? 4 : 1;
    if (const char* q = std::getenv("TRANSLUME_GL_QUARTERS")) t.quarters = std::atoi(q) != 0;
    if (const char* b = std::getenv("TRANSLUME_GL_LINE_BLOCK")) t.line_block = std::clamp(std::atoi(b), 1, 16);
    if (const char* l = std::getenv("TRANSLUME_GL_LINE_PCR")) t.line_pcr = std::atoi(l) != 0;
    if (const char* c = std::getenv("TRANSLUME_GL_SHADER_CLEAR")) t.shader_clear = std::atoi(c) != 0;
    if (const char* f = std::getenv("TRANSLUME_GL_FLUSH_EVERY")) t.flush_every = std::max(0, std::atoi(f));
    return t;
  }();
  return tuning;
}

}  // namespace gl_internal

std::string GlShaderTuning() {
  const gl_internal::Tuning& t = gl_internal::GetTuning();
  return fmt::format("{} ({}, {}-invocation groups, {} field(s) per value in batches, single "
                     "fields {}, line smoother {}{}{}; TRANSLUME_GL_TUNING=gpu|llvmpipe overrides)",
                     t.images ? "llvmpipe" : "gpu",
                     t.images ? "image buffers, z-column invocations" : "storage buffers, one node per invocation",
                     t.group, t.pack_fields, t.quarters ? "in quarter rows" : "plain",
                     t.line_pcr ? fmt::format("by cyclic reduction where a column fits a work group, else in blocks of {}",
                                              t.line_block)
                                : fmt::format("in blocks of {}", t.line_block),
                     t.shader_clear && !t.images ? ", clears and copies by shader" : "",
                     t.flush_every > 0 ? fmt::format(", a flush every {} dispatches", t.flush_every) : "");
}

namespace gl_internal {

// The program of solver/shaders/NAME.comp, compiled once with `defines` (e.g. "#define X\n").
GLuint Program(const std::string& name, const std::string& defines) {
  static std::map<std::string, GLuint> cache;
  if (auto it = cache.find(name + defines); it != cache.end()) return it->second;
  const gl::EmbeddedShader& file = FindShader("solver/shaders/" + name + ".comp");
  const GLuint program =
      CompileProgram(FindShader("solver/shaders/common.glsl"), defines, file.name, file.source);
  cache[name + defines] = program;
  return program;
}

namespace {

int64_t dispatch_count = 0;

// TRANSLUME_GL_PROFILE=2's key: the shader, its defines, threads and fields.
std::string ProfileKey(const char* name, const char* defines, int64_t threads, int fields) {
  std::string d;
  for (std::istringstream in(defines ? defines : ""); in >> std::ws && !in.eof();) {
    std::string word;
    in >> word;
    if (word != "#define") d += (d.empty() ? "" : " ") + word;
  }
  return fmt::format("{} [{}] {} x {}", name, d, threads, fields);
}

// Work groups (x, y) for `threads` threads: Tuning::group per group, at most 65535 groups
// along x.
std::pair<int64_t, int64_t> Tiling(int64_t threads) {
  const int64_t g = GetTuning().group;
  const int64_t groups = std::max<int64_t>(1, (threads + g - 1) / g);
  const int64_t gx = std::min<int64_t>(groups, 65535);
  return {gx, (groups + gx - 1) / gx};
}

// Binds `buffers` to bindings 0.., sets int uniforms at locations 0.. and an optional float
// uniform, and dispatches `threads` threads per field (Tuning::group per group, tiled under 65535
// groups per dimension) for `fields` fields (work-group z), followed by a shader-storage
// barrier. Returns the number of work groups per field.
int64_t Dispatch(const char* name, std::initializer_list<const Buffer*> buffers,
                 std::initializer_list<int> ints, int64_t threads, int fields, int float_location,
                 float float_value, const char* defines) {
  const GLuint prog = Program(name, defines);
  api.UseProgram(prog);
  GLuint b = 0;
  const bool images = GetTuning().images;
  for (const Buffer* buf : buffers) {
    if (images)
      buf->BindImage(b++);
    else
      api.BindBufferBase(GL_SHADER_STORAGE_BUFFER, b++, buf->id());
  }
  GLint loc = 0;
  for (int v : ints) api.Uniform1i(loc++, v);
  if (float_location >= 0) api.Uniform1f(float_location, float_value);
  const auto [gx, gy] = Tiling(threads);
  gl::Profiler& profile = gl::Profiler::Get();  // (TRANSLUME_GL_PROFILE)
  if (profile.on()) profile.Before();
  api.DispatchCompute(GLuint(gx), GLuint(gy), GLuint(fields));
  ++dispatch_count;
  if (const int every = GetTuning().flush_every; every > 0 && dispatch_count % every == 0) api.Flush();
  if (profile.on()) profile.After(profile.detailed() ? ProfileKey(name, defines, threads, fields) : name);
  api.MemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT | GL_SHADER_IMAGE_ACCESS_BARRIER_BIT);
  return gx * gy;
}

}  // namespace

int64_t DispatchCount() { return dispatch_count; }

int64_t LoopBudget() { return GlContext::Get().info().loop_budget; }

namespace {
// The fewest invocations among which n elements of `loops` inner-loop iterations each keep
// every invocation's count (each element one more for the grid-stride loop itself) within
// LoopBudget(), kLoopSlack spare; 1 where there is no budget.
int64_t BudgetThreads(int64_t n, int64_t loops) {
  const int64_t budget = LoopBudget();
  if (budget <= 0) return 1;
  const int64_t per_invocation = std::max<int64_t>(1, (budget - kLoopSlack) / (loops + 1));
  return (n + per_invocation - 1) / per_invocation;
}
}  // namespace

int64_t FlatThreads(int64_t n, int64_t loops) {
  const int groups = GetTuning().flat_groups;
  if (groups <= 0) return n;
  return std::min(n, std::max(int64_t(groups) * GetTuning().group, BudgetThreads(n, loops)));
}

int ColumnLength(const GridShape& s) { return GetTuning().columns ? int(s.nz) : 1; }

int64_t ColumnThreads(const GridShape& s) {
  const int64_t kz = ColumnLength(s);
  return s.nx * s.ny * ((s.nz + kz - 1) / kz);
}

// With one partial sum per invocation, two work groups per field: reduce.comp adds the
// partial sums up in one invocation per field.
int64_t DotThreads(int64_t n) {
  return GetTuning().invocation_sums ? std::min(n, std::max<int64_t>(2 * GetTuning().group, BudgetThreads(n, 0)))
                                     : FlatThreads(n, 0);
}

int64_t DotPartials(int64_t threads) {
  return WorkGroups(threads) * (GetTuning().invocation_sums ? GetTuning().group : 1);
}

int64_t WorkGroups(int64_t threads) {
  const auto [gx, gy] = Tiling(threads);
  return gx * gy;
}

int64_t Run(const char* name, std::initializer_list<const Buffer*> buffers,
            std::initializer_list<int> ints, int64_t threads, int float_location,
            float float_value, const char* defines) {
  return Dispatch(name, buffers, ints, threads, 1, float_location, float_value, defines);
}

int64_t RunBatch(const char* name, std::initializer_list<const Buffer*> buffers,
                 std::initializer_list<int> ints, int64_t threads, int fields,
                 const char* defines) {
  return Dispatch(name, buffers, ints, threads, fields, -1, 0, defines);
}

bool CopyOrZeroByShader(const Buffer* src, Buffer& dst, int64_t bytes) {
  if (!GetTuning().shader_clear || GetTuning().images || bytes % 16 != 0) return false;
  const int64_t n4 = bytes / 16;
  // (Zeroing binds dst as the unread src.)
  Run("copy", {src ? src : &dst, &dst}, {int(n4)}, FlatThreads(n4), -1, 0, src ? "" : "#define ZERO\n");
  api.MemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT);  // (an Upload or a GL copy after it lands after it)
  return true;
}

}  // namespace gl_internal

using gl::api;
using gl_internal::CompileProgram;
using gl_internal::FindShader;

void CompileGlShaderForTest(const std::string& file_name, const std::string& source) {
  GlContext::Get();
  const GLuint program =
      CompileProgram(FindShader("solver/shaders/common.glsl"), "", file_name, source.c_str());
  api.DeleteProgram(program);
}


GlMultigridSolver::GlMultigridSolver(const GridShape& shape, double h, const MultigridOptions& options)
    : impl_(std::make_unique<Impl>()) {
  if (std::string err = options.Validate(); !err.empty())
    throw InputError("multigrid options: " + err);
  if (shape.size() >= (int64_t(1) << 31))
    throw InputError(fmt::format("--backend gl: grid {} has 2^31 nodes or more; use --backend cpu",
                                 shape.ToString()));
  // One invocation solves a whole z-line (smooth.comp, factor.comp: about 2 nz + 2 loop
  // iterations), which llvmpipe's loop budget (GlInfo::loop_budget) must hold.
  if (const int64_t budget = gl_internal::LoopBudget();
      budget > 0 && 2 * shape.nz + 2 + gl_internal::kLoopSlack > budget)
    throw InputError(fmt::format("--backend gl: grid {} is {} nodes deep, and llvmpipe runs z-lines of at most {} "
                                 "nodes; use --backend cpu", shape.ToString(), shape.nz,
                                 (budget - gl_internal::kLoopSlack - 2) / 2));
  Impl& I = *impl_;
  I.options = options.WithCycleDefaults(true, shape.size());
  I.n0 = shape.size();
  for (MultigridLevel& geo : BuildMultigridHierarchy(shape, h, 64, *I.options.z_coarsening)) {
    auto L = std::make_unique<GLevel>();
    L->geo = std::move(geo);
    L->s = L->geo.grid.shape;
    L->n = L->s.size();
    I.levels.push_back(std::move(L));
  }
  for (size_t l = 0; l < I.levels.size(); ++l) {
    GLevel& L = *I.levels[l];
    const int64_t bytes = L.n * 4;
    std::vector<float> geo;
    for (int a = 0; a < 3; ++a)
      for (int64_t i = 0; i < L.s.n(a); ++i) geo.push_back(float(L.geo.grid.Width(a, i)));
    for (int a = 0; a < 3; ++a)
      for (int64_t i = 0; i < L.s.n(a); ++i)
        geo.push_back(i + 1 < L.s.n(a) ? float(L.geo.grid.Gap(a, i)) : 1.0f);
    L.geometry.Alloc(geo.size() * 4, geo.data());
    for (Buffer* b : {&L.kappa, &L.mu, &L.cx, &L.cy, &L.cz, &L.diag, &L.sigma, &L.inv, &L.luc})
      b->Alloc(bytes);
    if (l > 0) {
      // R applied to ones from the finer level: the weights that make restricted kappa and mu
      // averages.
      GLevel& F = *I.levels[l - 1];
      const int64_t mx = F.geo.to_coarse[0].n_coarse, my = F.geo.to_coarse[1].n_coarse;
      std::vector<float> ones(F.n, 1.0f);
      std::vector<float> rn(L.n), ta(mx * F.s.ny * F.s.nz), tb(mx * my * F.s.nz);
      Restrict3(F.geo, ones.data(), rn.data(), ta.data(), tb.data());
      L.rnorm.Alloc(bytes, rn.data());
    }
  }
  // Fields per batch: every per-field buffer (the largest: nb n0 doubles) within the largest
  // shader storage block, nb n0 below 2^31 (the shaders' int indices), and at most 4096.
  const GlInfo& info = GlContext::Get().info();
  int64_t most = std::min<int64_t>({info.max_ssbo_bytes / (I.n0 * 8), ((int64_t(1) << 31) - 1) / I.n0,
                                    info.max_work_group_count[2], 4096});
  if (gl_internal::GetTuning().images) {  // ... and within the largest buffer texture
    GLint texels = 0;
    api.GetIntegerv(GL_MAX_TEXTURE_BUFFER_SIZE, &texels);
    most = std::min<int64_t>(most, texels / I.n0);
  }
  // Packed batches (Impl::Packed) hold whole groups of four fields.
  if (gl_internal::GetTuning().pack_fields == 4 && most >= 4) most = most / 4 * 4;
  I.max_batch = int(std::max<int64_t>(1, most));
  I.tail_nodes = gl_internal::GetTuning().tail_nodes;
  I.tail_group = gl_internal::GetTuning().tail_group;
  I.pack_fields = gl_internal::GetTuning().pack_fields;
  // Quarter rows: an even width, so that the zebra sweeps' colours agree across quarters.
  const GridShape& s0 = I.levels[0]->s;
  I.qw = int(2 * ((s0.nx + 7) / 8));
  I.nq = int64_t(I.qw) * s0.ny * s0.nz;
  I.quarters = gl_internal::GetTuning().quarters;
  I.line_pcr = gl_internal::GetTuning().line_pcr;
  I.PackLevels();
  I.Reserve(1);
}

// multigrid.glsl's metadata rows: kMgMeta ints per level, the per-axis part from kMgAxis on
// (tail.comp's offsets: coefficients from 3, work values from 9).
constexpr int kMgMeta = 36, kMgAxis = 14;
// multigrid.glsl's kMgTaps: the most fine nodes one coarse node gathers along one axis.
constexpr int64_t kMgTaps = 4;
// The coarsest level is inverted densely (dense_coarse) up to this many nodes.
constexpr int64_t kDenseCoarsestNodes = 1024;

void GlMultigridSolver::Impl::PackLevels() {
  const size_t nl = levels.size();
  tail_level = nl;
  for (size_t l = 0; l < nl; ++l)
    if (levels[l]->n <= tail_nodes) {
      tail_level = l;
      break;
    }
  // Where one tail invocation would loop past llvmpipe's budget (LoopBudget), start
  // the tail lower. Measured against the budget left over (a counted loop appended to
  // tail.comp, single fields, on llvmpipe: 31 tails of 9 grids, groups of 8, 32 and 64),
  // TailLoopIterations over-counts every one, 1.06-1.8x below 1000 iterations and 1.8-3.2x
  // above; kLoopSlack covers loops it might still miss.
  for (const int64_t budget = gl_internal::LoopBudget();
       budget > 0 && tail_level + 2 <= nl && TailLoopIterations(tail_level) + gl_internal::kLoopSlack > budget;)
    ++tail_level;
  if (tail_level + 2 > nl) tail_level = nl;  // fewer than two levels: the per-level path is as short
  std::vector<int> idx(nl * kMgMeta, 0);
  std::vector<float> wts;
  auto row = [&](size_t l) { return &idx[l * kMgMeta]; };
  tail_coef_offset.assign(nl, 0);
  int64_t coef = 0, work = 0;
  for (size_t l = 0; l < nl; ++l) {
    const GLevel& L = *levels[l];
    row(l)[0] = int(L.s.nx), row(l)[1] = int(L.s.ny), row(l)[2] = int(L.s.nz);
    if (l >= tail_level) {
      tail_coef_offset[l] = coef;
      for (int c = 0; c < 6; ++c) row(l)[3 + c] = int(coef + c * L.n);  // cx cy cz inv luc sigma
      coef += 6 * L.n;
      for (int c = 0; c < 3; ++c, work += L.n) row(l)[9 + c] = int(work);  // b x r
    }
    if (l + 1 == nl) continue;
    for (int a = 0; a < 3; ++a) {
      const AxisTransfer& tr = L.geo.to_coarse[a];
      for (int64_t c = 0; c < tr.n_coarse; ++c)
        TL_CHECK(tr.g_start[c + 1] - tr.g_start[c] <= kMgTaps);
      const int m = int(l) * kMgMeta + kMgAxis + 7 * a;
      idx[m] = int(tr.n_fine), idx[m + 1] = int(tr.n_coarse);
      idx[m + 2] = int(idx.size());
      idx.insert(idx.end(), tr.g_start.begin(), tr.g_start.end());
      idx[m + 3] = int(idx.size());
      idx.insert(idx.end(), tr.g_idx.begin(), tr.g_idx.end());
      idx[m + 4] = int(wts.size());
      wts.insert(wts.end(), tr.g_w.begin(), tr.g_w.end());
      idx[m + 5] = int(idx.size());
      idx[m + 6] = int(wts.size());
      for (int64_t f = 0; f < tr.n_fine; ++f) {
        idx.push_back(int(tr.lo[f]));
        idx.push_back(int(tr.hi[f]));
        wts.push_back(float(tr.wlo[f]));
        wts.push_back(float(tr.whi[f]));
      }
    }
  }
  xfer_idx.Alloc(int64_t(idx.size()) * 4, idx.data(), Elem::kInt);
  xfer_w.Alloc(int64_t(wts.size()) * 4, wts.data());
  if (tail_level < nl) tail_coef.Alloc(coef * 4);
  // With the whole hierarchy in the tail, a fused CG iteration (CgIterationInTail) keeps p and
  // q of the finest level after the levels' b, x, r.
  tail_stride = work + (tail_level == 0 ? 2 * levels[0]->n : 0);
}

int64_t GlMultigridSolver::Impl::TailLoopIterations(size_t first) const {
  // llvmpipe counts a loop of k iterations as k + 1 (the pass that leaves it counts too), per
  // chunk of 8 invocations, so a group loop counts its slowest lane. Loops of a constant count
  // (four fields, two taps) count as loops though the compiler may unroll them.
  const int64_t g = tail_group;
  // A loop of tail.comp's group over `items` (its invocation's share, rounded up), each
  // iteration running inner loops of `inner` counted iterations.
  auto over = [&](int64_t items, int64_t inner) { return (items + g - 1) / g * (1 + inner) + 1; };
  // HalfSweep: its columns, each SmoothLine's two loops of nz and nz - 1 nodes (in blocks of
  // B: a loop over the blocks, each two loops of B).
  const int64_t B = GetTuning().line_block;
  auto half_sweep = [&](const GridShape& s) {
    if (B == 1) return over((s.nx + 1) / 2 * s.ny, 2 * s.nz + 1);
    return over((s.nx + 1) / 2 * s.ny, ((s.nz + B - 1) / B + (s.nz - 1 + B - 1) / B) * (2 * B + 3) + 2);
  };
  // StencilLevel: its columns of kz nodes (or its nodes), each ResidualColumn's loop.
  auto stencil = [&](const GridShape& s) {
    const int64_t kz = GetTuning().columns ? s.nz : 1;
    return over(s.nx * s.ny * ((s.nz + kz - 1) / kz), kz + 1);
  };
  const size_t last = levels.size() - 1;
  const int64_t n0 = levels[first]->n;
  // main's b in and x out (FIELDS4 on per-field buffers: a loop over four fields each); the
  // V-cycle's loops over the levels (x = 0, down, up).
  int64_t it = 2 * over(n0, 5) + 3 * int64_t(levels.size() - first + 1);
  for (size_t l = first; l < last; ++l) {
    const GLevel& L = *levels[l];
    const int nu = l == 0 ? options.pre_smoothing : options.coarse_smoothing;
    // x = 0; nu half-sweep pairs down and up (each pair one iteration of its own loop); the
    // residual; the prolongation (ProlongAt's loops of 2, then 2 x 2).
    it += over(L.n, 0) + 2 * (nu * (1 + 2 * half_sweep(L.s)) + 1) + stencil(L.s) + over(L.n, 3 + 6);
    // The restriction: per coarse node three MgGathers of t taps, the nested z, y, x sums.
    int64_t t[3];
    for (int a = 0; a < 3; ++a) {
      const std::vector<int64_t>& gs = L.geo.to_coarse[a].g_start;
      t[a] = 0;
      for (size_t c = 0; c + 1 < gs.size(); ++c) t[a] = std::max(t[a], gs[c + 1] - gs[c]);
    }
    it += over(levels[l + 1]->n, (t[0] + 1) + (t[1] + 1) + (t[2] + 1) + (t[2] + 1) + t[2] * (t[1] + 1) +
                                     t[2] * t[1] * (t[0] + 1));
  }
  // The coarsest level: x = 0, then DenseRow's n per row or coarse_sweeps sweep quadruples.
  const GLevel& C = *levels[last];
  it += over(C.n, 0) + (C.n <= kDenseCoarsestNodes ? over(C.n, C.n + 1)
                                                   : coarse_sweeps * (1 + 4 * half_sweep(C.s)) + 1);
  if (first == 0)  // CG_ITERATION: p in; q = A p; p.q; x, r (four fields); r.r, r.z; p out;
    // three GroupSums over the group; four loops over four fields.
    it += over(n0, 0) + stencil(levels[0]->s) + over(n0, 0) + over(n0, 5) + over(n0, 0) + over(n0, 0) +
          3 * (g + 1) + 4 * 5;
  return it;
}

void GlMultigridSolver::Impl::CopyTailCoefficients() {
  for (size_t l = tail_level; l < levels.size(); ++l) {
    GLevel& L = *levels[l];
    const int64_t at = tail_coef_offset[l] * 4, bytes = L.n * 4;
    int c = 0;
    for (const Buffer* b : {&L.cx, &L.cy, &L.cz, &L.inv, &L.luc, &L.sigma})
      tail_coef.CopyFrom(*b, bytes, 0, at + bytes * c++);
  }
}

void GlMultigridSolver::Impl::Tail(const Buffer& b, Buffer& x, int nb) {
  const Buffer& minv = dense_coarse ? coarse_inverse : tail_coef;  // unread without dense
  // One work group of tail_group invocations per field (Run's tiling makes one group of
  // `group` threads).
  const bool four = Packed(nb);
  const std::string defines = fmt::format("#define TL_GROUP {}\n{}{}", tail_group,
                                          four ? "#define FIELDS4\n" : "", packed ? "#define PACKED_IO\n" : "");
  RunBatch("tail", {&tail_coef, &xfer_idx, &xfer_w, &minv, &b, &x, four ? &tail_work4 : &tail_work},
           {int(tail_level), int(levels.size() - tail_level), options.pre_smoothing, options.coarse_smoothing,
            dense_coarse ? 1 : 0, coarse_sweeps, int(tail_stride), GetTuning().columns ? 1 : 0, nb},
           GetTuning().group, four ? (nb + 3) / 4 : nb, defines.c_str());
}

bool GlMultigridSolver::Impl::CgIterationInTail(int nb) const {
  return tail_level == 0 && Packed(nb);
}

void GlMultigridSolver::Impl::AllocTailWork(int fields) {
  tail_work.Alloc(tail_stride * 4 * (pack_fields == 4 ? Slots4(fields) : fields));
  tail_work4.ViewOf(tail_work, Elem::kVec4);
}

void GlMultigridSolver::SetCoarseTail(int64_t max_nodes) {
  Impl& I = *impl_;
  I.tail_nodes = max_nodes;
  I.PackLevels();
  if (I.tail_level == I.levels.size()) return;
  I.AllocTailWork(std::max(I.capacity, 1));
  if (I.coefficients_set) I.CopyTailCoefficients();
}

int GlMultigridSolver::coarse_tail_levels() const {
  return int(impl_->levels.size() - impl_->tail_level);
}

void GlMultigridSolver::Impl::Reserve(int fields) {
  TL_CHECK(fields >= 1 && fields <= max_batch);
  if (fields <= capacity) return;
  const int64_t slots = pack_fields == 4 ? Slots4(fields) : fields;
  // Quarter rows (one field) may need more room than one field's values: the padding.
  const int64_t rows = quarters ? nq * 16 : 0;
  for (size_t l = 0; l < levels.size(); ++l) {
    GLevel& L = *levels[l];
    for (Buffer* b : {&L.b, &L.x, &L.r}) b->Alloc(std::max(L.n * 4 * slots, l == 0 ? rows : 0));
  }
  for (Buffer* b : {&r, &z, &p, &q}) b->Alloc(std::max(n0 * 4 * slots, rows));
  r4.ViewOf(r, Elem::kVec4);
  z4.ViewOf(z, Elem::kVec4);
  p4.ViewOf(p, Elem::kVec4);
  q4.ViewOf(q, Elem::kVec4);
  if (pack_fields == 4 || quarters) {
    b_packed.Alloc(std::max(n0 * 4 * slots, rows), nullptr, Elem::kVec4);
    x_packed.Alloc(std::max(n0 * 8 * slots, 2 * rows), nullptr, Elem::kDouble);
  }
  for (size_t l = 0; l < levels.size(); ++l) {
    GLevel& L = *levels[l];
    L.b4.ViewOf(l == 0 ? q : L.b, Elem::kVec4);
    L.x4.ViewOf(L.x, Elem::kVec4);
    L.r4.ViewOf(L.r, Elem::kVec4);
  }
  xd.Alloc(n0 * 8 * fields, nullptr, Elem::kDouble);
  if (tail_level < levels.size()) AllocTailWork(fields);
  partial.Alloc(DotPartials(DotThreads(n0)) * 2 * 8 * fields, nullptr, Elem::kDouble);
  scal.Alloc(kCgStride * 8 * fields, nullptr, Elem::kDouble);
  hist.Alloc(int64_t(options.max_iterations) * 8 * fields, nullptr, Elem::kDouble);
  capacity = fields;
}

void GlMultigridSolver::Impl::SetPackFields(int k) {
  TL_CHECK(k == 1 || k == 4);
  pack_fields = k;
  const int fields = capacity;
  capacity = 0;
  Reserve(fields);
}

void GlMultigridSolver::Impl::SetQuarters(bool on) {
  quarters = on;
  quarter_coefficients_stale = true;
  const int fields = capacity;
  capacity = 0;
  Reserve(fields);
}

void GlMultigridSolver::Impl::QuarterCoefficients() {
  TL_CHECK(quartered);
  GLevel& L = *levels[0];
  const std::pair<const Buffer*, Buffer*> pairs[] = {{&L.cx, &cx_q},   {&L.cy, &cy_q},   {&L.cz, &cz_q},
                                                     {&L.inv, &inv_q}, {&L.luc, &luc_q}, {&L.sigma, &sigma_q}};
  for (const auto& [plain, rows] : pairs) {
    if (rows->id() == 0) rows->Alloc(nq * 16, nullptr, Elem::kVec4);
    Pack(*plain, *rows, 1);
  }
}

void GlMultigridSolver::Impl::Pack(const Buffer& per_field, Buffer& packed4, int nb, bool doubles) {
  RunPack(per_field, packed4, nb, doubles, false);
}

void GlMultigridSolver::Impl::Unpack(const Buffer& packed4, Buffer& per_field, int nb, bool doubles) {
  RunPack(per_field, packed4, nb, doubles, true);
}

void GlMultigridSolver::Impl::RunPack(const Buffer& per_field, const Buffer& packed4, int nb, bool doubles,
                                      bool unpack) {
  const std::string defines = std::string(quartered ? "#define QUARTERS\n" : "") +
                              (doubles ? "#define DOUBLE\n" : "") + (unpack ? "#define UNPACK\n" : "");
  if (quartered)
    RunBatch("pack", {&per_field, &packed4}, {int(nq), 1, int(levels[0]->s.nx), qw}, FlatThreads(nq), 1,
             defines.c_str());
  else
    RunBatch("pack", {&per_field, &packed4}, {int(n0), nb}, FlatThreads(n0), (nb + 3) / 4, defines.c_str());
}

GlMultigridSolver::~GlMultigridSolver() = default;

int GlMultigridSolver::num_levels() const { return int(impl_->levels.size()); }

void GlMultigridSolver::SetCoefficients(const float* kappa, const float* mu, double C) {
  Impl& I = *impl_;
  for (size_t l = 0; l < I.levels.size(); ++l) {
    GLevel& L = *I.levels[l];
    if (l == 0) {
      L.kappa.Upload(kappa, L.n * 4);
      L.mu.Upload(mu, L.n * 4);
    } else {
      GLevel& F = *I.levels[l - 1];
      I.Restrict(l - 1, F.kappa, L.kappa, 1);
      I.Restrict(l - 1, F.mu, L.mu, 1);
      Run("divide", {&L.kappa, &L.rnorm}, {int(L.n)}, FlatThreads(L.n));
      Run("divide", {&L.mu, &L.rnorm}, {int(L.n)}, FlatThreads(L.n));
    }
    Run("assemble", {&L.kappa, &L.mu, &L.geometry, &L.cx, &L.cy, &L.cz, &L.diag, &L.sigma},
        {int(L.s.nx), int(L.s.ny), int(L.s.nz)}, FlatThreads(L.n), 3, float(1.0 / (2.0 * C)));
    Run("factor", {&L.cz, &L.diag, &L.inv, &L.luc}, {int(L.s.nx), int(L.s.ny), int(L.s.nz)},
        L.s.nx * L.s.ny);
  }
  // The coarsest level: an exact dense inverse when it is small (one dispatch per V-cycle
  // instead of many sweeps); the few values travel to the host and back once per update.
  GLevel& Lc = *I.levels.back();
  I.dense_coarse = Lc.n <= kDenseCoarsestNodes;
  if (I.dense_coarse) {
    const int64_t n = Lc.n;
    const GridShape& s = Lc.s;
    std::vector<float> cx(n), cy(n), cz(n), dg(n);
    Lc.cx.Download(cx.data(), n * 4);
    Lc.cy.Download(cy.data(), n * 4);
    Lc.cz.Download(cz.data(), n * 4);
    Lc.diag.Download(dg.data(), n * 4);
    Eigen::MatrixXd M = Eigen::MatrixXd::Zero(n, n);
    for (int64_t k = 0; k < s.nz; ++k)
      for (int64_t j = 0; j < s.ny; ++j)
        for (int64_t i = 0; i < s.nx; ++i) {
          const int64_t p = s.index(i, j, k);
          M(p, p) = dg[p];
          auto couple = [&](int64_t q, float c) { M(p, q) = M(q, p) = -double(c); };
          if (i + 1 < s.nx) couple(p + 1, cx[p]);
          if (j + 1 < s.ny) couple(p + s.nx, cy[p]);
          if (k + 1 < s.nz) couple(p + s.nx * s.ny, cz[p]);
        }
    const Eigen::MatrixXd inv = M.llt().solve(Eigen::MatrixXd::Identity(n, n));
    std::vector<float> f(n * n);
    for (int64_t r = 0; r < n; ++r)
      for (int64_t c = 0; c < n; ++c) f[r * n + c] = float(inv(r, c));
    I.coarse_inverse.Alloc(n * n * 4, f.data());
  }
  I.coefficients_set = true;
  if (I.tail_level < I.levels.size()) I.CopyTailCoefficients();
  I.quarter_coefficients_stale = true;  // packed by the next quartered solve
}

void GlMultigridSolver::Apply(const float* x, float* y) {
  Impl& I = *impl_;
  GLevel& L = *I.levels[0];
  L.x.Upload(x, L.n * 4);
  I.Stencil(L, L.x, L.x, I.q, 1, 1);
  I.q.Download(y, L.n * 4);
}

void GlMultigridSolver::Impl::VCycle(size_t l, const Buffer& b, Buffer& x, int nb,
                                     bool from_zero, int sweeps) {
  GLevel& L = *levels[l];
  if (l == tail_level) {
    Tail(b, x, nb);
    return;
  }
  if (from_zero || l + 1 == levels.size()) x.Zero();
  if (l + 1 == levels.size()) {
    if (dense_coarse) {
      RunFields("dense_solve", {&coarse_inverse, &b, &x}, {int(L.n)}, L.n, nb);
      return;
    }
    for (int s = 0; s < coarse_sweeps; ++s) {
      Smooth(L, b, x, 0, nb);
      Smooth(L, b, x, 1, nb);
      Smooth(L, b, x, 1, nb);
      Smooth(L, b, x, 0, nb);
    }
    return;
  }
  const int nu = sweeps > 0 ? sweeps : options.SweepsOnLevel(l);
  for (int s = 0; s < nu; ++s) {
    Smooth(L, b, x, 0, nb);
    Smooth(L, b, x, 1, nb);
  }
  Stencil(L, x, b, LevelR(L), 0, nb);
  GLevel& C = *levels[l + 1];
  Restrict(l, LevelR(L), LevelB(C), nb);
  VCycle(l + 1, LevelB(C), LevelX(C), nb, true, sweeps);
  ProlongAdd(l, LevelX(C), x, nb);
  for (int s = 0; s < nu; ++s) {
    Smooth(L, b, x, 1, nb);
    Smooth(L, b, x, 0, nb);
  }
}

void GlMultigridSolver::Impl::Precondition(const Buffer& r, Buffer& z, int nb) {
  OnFinest(r, z, nb, [&](const Buffer& b, Buffer& x) { VCycle(0, b, x, nb); });
}

void GlMultigridSolver::Impl::FullMultigrid(const Buffer& r, Buffer& z, int nb) {
  OnFinest(r, z, nb, [&](const Buffer& b, Buffer& x) { FullMultigridLevels(b, x, nb); });
}

void GlMultigridSolver::Impl::FullMultigridLevels(const Buffer& r, Buffer& z, int nb) {
  // Down to the coarse tail (one V-cycle over the tail's levels there) or the coarsest level.
  const size_t top = FullMultigridTop();
  const Buffer* fine = &r;
  for (size_t l = 0; l < top; ++l) {
    Restrict(l, *fine, LevelB(*levels[l + 1]), nb);
    fine = &LevelB(*levels[l + 1]);
  }
  VCycle(top, LevelB(*levels[top]), LevelX(*levels[top]), nb);
  for (size_t l = top; l-- > 0;) {
    GLevel& L = *levels[l];
    Buffer& x = l == 0 ? z : LevelX(L);
    x.Zero();
    ProlongAdd(l, LevelX(*levels[l + 1]), x, nb);
    if (l > 0) {
      VCycle(l, LevelB(L), x, nb, false, 1);
    } else {
      for (int s = 0; s < options.full_multigrid_sweeps; ++s) {
        Smooth(L, r, z, s % 2, nb);
        Smooth(L, r, z, 1 - s % 2, nb);
      }
    }
  }
}

// The cpu solver's algorithm (multigrid.cc) on nb fields in lockstep. The per-field scalars
// (alpha = rz / pq, beta = rz_new / rz, the convergence test rr <= (tol ||b||)^2) live on the
// GPU (scal, cg_update.comp, cg_scalars.comp): a field that meets the test freezes (alpha = 0)
// while the others go on. The host reads the scalars back once at the start and then every
// check_every iterations; when no field is active it verifies every frozen field's true
// residual b - A x (double x) and restarts those that miss the tolerance (at most 3 times,
// then "stagnated"), as the cpu solver does.
std::vector<SolveSummary> GlMultigridSolver::Impl::SolveDevice(const Buffer& b_fields, Buffer& x_fields,
                                                               int nb, bool grouped) {
  const auto t0 = std::chrono::steady_clock::now();
  Reserve(nb);
  GLevel& L = *levels[0];
  // The layout of the whole solve: packed (four fields per value) or one field per n values.
  struct Layout {
    bool& flag;
    Layout(bool& f, bool on) : flag(f) { flag = on; }
    ~Layout() { flag = false; }
  } layout(packed, Packed(nb)), quarter_rows(quartered, Quartered(nb));
  if (quartered && quarter_coefficients_stale) {
    QuarterCoefficients();
    quarter_coefficients_stale = false;
  }
  TL_CHECK(!grouped || packed);
  const bool vec4s = packed || quartered;
  // Whether b and x are packed here, around the solve.
  const bool pack_here = vec4s && !grouped;
  if (pack_here) {
    Pack(b_fields, b_packed, nb);
    Pack(x_fields, x_packed, nb, true);
  }
  const Buffer& b = pack_here ? b_packed : b_fields;
  Buffer& x = pack_here ? x_packed : x_fields;
  Buffer &r = vec4s ? r4 : this->r, &z = vec4s ? z4 : this->z;
  Buffer &p = vec4s ? p4 : this->p, &q = vec4s ? q4 : this->q;
  // Bytes of the CG vectors r .. q in the current layout.
  const int64_t vector_bytes = quartered ? nq * 16 : n0 * 4 * (packed ? Slots4(nb) : nb);
  const int64_t n = n0;
  const int max_it = options.max_iterations;
  const double tol = options.tolerance;
  std::vector<SolveSummary> sums(nb);
  std::vector<char> done(nb, 0);
  std::vector<int> restarts(nb, 0);
  std::vector<double> sc(int64_t(nb) * kCgStride, 0.0);
  auto at = [&](int f, int slot) -> double& { return sc[int64_t(f) * kCgStride + slot]; };
  auto read = [&] { scal.Download(sc.data(), int64_t(sc.size()) * 8); };
  auto finish = [&](int f, bool converged, std::string message) {
    const double bb = at(f, kCgBb);
    sums[f].final_residual = bb > 0 ? std::sqrt(at(f, kCgRr) / bb) : 0.0;
    sums[f].converged = converged;
    sums[f].message = std::move(message);
    done[f] = 1;
  };
  // rr of every field from its true residual r = b - A x; r is then the restart's residual.
  auto true_residual = [&] {
    Stencil(L, x, b, r, 0, nb, true);
    Dot(r, r, kCgRr, nb);
    read();
  };
  auto restart = [&] {
    Precondition(r, z, nb);
    p.CopyFrom(z, vector_bytes);
    Dot(r, z, kCgRz, nb);
  };

  scal.Zero();
  Dot(b, b, kCgBb, nb);
  true_residual();
  bool any = false;
  for (int f = 0; f < nb; ++f) {
    const double bb = at(f, kCgBb);
    if (bb == 0) {
      if (grouped) {
        // Component f % 4 of group f / 4's n nodes.
        std::vector<double> group(4 * n);
        x.Download(group.data(), 4 * n * 8, int64_t(f / 4) * 4 * n * 8);
        for (int64_t e = 0; e < n; ++e) group[4 * e + f % 4] = 0.0;
        x.Upload(group.data(), 4 * n * 8, int64_t(f / 4) * 4 * n * 8);
      } else {
        const std::vector<double> zeros(n, 0.0);
        x_fields.Upload(zeros.data(), n * 8, int64_t(f) * n * 8);
        if (pack_here) Pack(x_fields, x_packed, nb, true);
      }
      at(f, kCgRr) = 0;
      finish(f, true, "zero right-hand side");
      continue;
    }
    sums[f].initial_residual = std::sqrt(at(f, kCgRr) / bb);
    if (sums[f].initial_residual <= tol) {
      finish(f, true, "");
      continue;
    }
    at(f, kCgActive) = 1;
    at(f, kCgTol2) = tol * tol * bb;
    any = true;
  }
  int it = 0;
  if (any) {
    scal.Upload(sc.data(), int64_t(sc.size()) * 8);
    // (With the coarse tail covering every level the pass would be one V-cycle from zero,
    // which CG's first iteration does better.)
    if (options.full_multigrid_start && FullMultigridTop() > 0) {
      // x += the full-multigrid approximation of A^-1 r on the active fields, then their new
      // true residuals (a field may already meet the tolerance).
      FullMultigrid(r, z, nb);
      CgUpdate({&x, &r, &z, &z, &scal}, "#define ADD\n", nb);
      true_residual();
      any = false;
      for (int f = 0; f < nb; ++f) {
        if (done[f]) continue;
        if (at(f, kCgRr) <= at(f, kCgTol2)) {
          at(f, kCgActive) = 0;
          finish(f, true, "");
        } else {
          any = true;
        }
      }
      scal.Upload(sc.data(), int64_t(sc.size()) * 8);
    }
    if (any) restart();
  }
  const bool fused = CgIterationInTail(nb);
  while (any && it < max_it) {
    if (fused) {
      const std::string defines =
          fmt::format("#define TL_GROUP {}\n#define FIELDS4\n#define CG_ITERATION\n", tail_group);
      RunBatch("tail", {&tail_coef, &xfer_idx, &xfer_w, dense_coarse ? &coarse_inverse : &tail_coef, &r, &p, &tail_work4, &x, &scal, &hist},
               {0, int(levels.size()), options.pre_smoothing, options.coarse_smoothing, dense_coarse ? 1 : 0,
                coarse_sweeps, int(tail_stride), GetTuning().columns ? 1 : 0, nb, max_it},
               GetTuning().group, (nb + 3) / 4, defines.c_str());
    } else {
      Stencil(L, p, p, q, 1, nb);
      Dot(p, q, kCgPq, nb);
      CgUpdate({&x, &r, &p, &q, &scal}, "", nb);
      // Precondition before looking at the residual: both dots from one pass.
      Precondition(r, z, nb);
      Dot2(r, r, z, kCgRr, nb);  // rr and rz_new
      CgUpdate({&p, &z, &z, &z, &scal}, "#define DIRECTION\n", nb);
      Run("cg_scalars", {&scal, &hist}, {nb, max_it}, nb);
    }
    ++it;
    if (it % check_every != 0 && it < max_it) continue;
    read();
    bool active = false;
    for (int f = 0; f < nb; ++f) active |= !done[f] && at(f, kCgActive) != 0;
    if (active) continue;
    true_residual();
    bool again = false;
    for (int f = 0; f < nb; ++f) {
      if (done[f]) continue;
      if (at(f, kCgRr) <= at(f, kCgTol2)) {
        finish(f, true, "");
      } else if (++restarts[f] > 3) {
        finish(f, false, "stagnated");
      } else {
        at(f, kCgActive) = 1;
        again = true;
      }
    }
    if (!again) break;
    scal.Upload(sc.data(), int64_t(sc.size()) * 8);
    restart();
  }
  bool left = false;
  for (int f = 0; f < nb; ++f) left |= !done[f];
  if (left) {
    true_residual();
    for (int f = 0; f < nb; ++f)
      if (!done[f]) finish(f, false, fmt::format("reached max_iterations = {}", max_it));
  }
  if (pack_here) Unpack(x_packed, x_fields, nb, true);
  std::vector<double> h(int64_t(nb) * max_it);
  if (it > 0) hist.Download(h.data(), int64_t(h.size()) * 8);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  for (int f = 0; f < nb; ++f) {
    SolveSummary& s = sums[f];
    s.iterations = int(at(f, kCgIter));
    for (int i = 0; i < std::min(s.iterations, max_it); ++i)
      s.history.push_back(std::sqrt(h[int64_t(f) * max_it + i] / at(f, kCgBb)));
    s.seconds = seconds;
  }
  return sums;
}

std::vector<SolveSummary> GlMultigridSolver::SolveBatch(int fields, const float* b_host,
                                                        float* x_host) {
  const auto t0 = std::chrono::steady_clock::now();
  Impl& I = *impl_;
  const int64_t n = I.n0;
  std::vector<SolveSummary> out;
  for (int first = 0; first < fields; first += I.max_batch) {
    const int nb = std::min(I.max_batch, fields - first);
    I.Reserve(nb);
    // b lives in the finest level's b buffer; the iterates in double (see residual.comp).
    I.levels[0]->b.Upload(b_host + first * n, nb * n * 4);
    std::vector<double> xd(x_host + first * n, x_host + (first + nb) * n);
    I.xd.Upload(xd.data(), nb * n * 8);
    for (SolveSummary& s : I.SolveDevice(I.levels[0]->b, I.xd, nb)) out.push_back(std::move(s));
    I.xd.Download(xd.data(), nb * n * 8);
    for (int64_t i = 0; i < nb * n; ++i) x_host[first * n + i] = float(xd[i]);
  }
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  for (SolveSummary& s : out) s.seconds = seconds;
  return out;
}

SolveSummary GlMultigridSolver::Solve(const float* b_host, float* x_host) {
  return SolveBatch(1, b_host, x_host)[0];
}

int GlMultigridSolver::max_batch() const { return impl_->max_batch; }

namespace {

// Median wall time of `repetitions` runs of `body`, which runs what it times `per_run` times
// (the result is per time); gl work is finished before and inside each run.
template <typename F>
double MedianSeconds(int repetitions, int per_run, F&& body) {
  std::vector<double> times;
  api.Finish();
  for (int r = 0; r < repetitions; ++r) {
    const auto t0 = std::chrono::steady_clock::now();
    body();
    api.Finish();
    times.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() /
                    per_run);
  }
  std::sort(times.begin(), times.end());
  return times[times.size() / 2];
}

}  // namespace

double GlMultigridSolver::TimeApply(int repetitions, int fields) {
  Impl& I = *impl_;
  TL_CHECK_MSG(fields >= 1 && fields <= I.capacity, "TimeApply: more fields than a batch has reserved");
  GLevel& L = *I.levels[0];
  return MedianSeconds(repetitions, 10, [&] {
    for (int k = 0; k < 10; ++k) I.Stencil(L, L.x, L.x, I.q, 1, fields);
  });
}

double GlMultigridSolver::TimeEmptyDispatch(int repetitions) {
  Impl& I = *impl_;
  return MedianSeconds(repetitions, 100, [&] {
    for (int k = 0; k < 100; ++k) Run("copy", {&I.q4, &I.q4}, {0}, 1);
  });
}

int64_t GlMultigridSolver::Dispatches() { return gl_internal::DispatchCount(); }

double GlMultigridSolver::TimeCopy(int64_t bytes, int repetitions) {
  if (GetTuning().images) {
    // llvmpipe: the device's memory is the host's, and its practical peak a host copy on every
    // thread (a copy shader there is bound by llvmpipe's cost per access, not by memory: it read
    // below the stencil's own rate).
    std::vector<char> src(size_t(bytes), 1), dst(size_t(bytes), 0);
    return MedianSeconds(repetitions, 1, [&] {
#pragma omp parallel
      {
        const int64_t nt = omp_get_num_threads(), id = omp_get_thread_num();
        const int64_t a = bytes * id / nt, b = bytes * (id + 1) / nt;
        std::memcpy(dst.data() + a, src.data() + a, size_t(b - a));
      }
    });
  }
  Buffer src, dst;
  const int64_t n4 = bytes / 16;
  src.Alloc(n4 * 16, nullptr, Elem::kVec4);
  dst.Alloc(n4 * 16, nullptr, Elem::kVec4);
  src.Zero();
  return MedianSeconds(repetitions, 10, [&] {
    for (int k = 0; k < 10; ++k) Run("copy", {&src, &dst}, {int(n4)}, FlatThreads(n4));
  });
}

int64_t GlMultigridSolver::ApplyBytes(int fields) const { return impl_->n0 * 4 * (4 + 2 * int64_t(fields)); }

std::string GlMultigridSolver::CopyReference() const {
  return GetTuning().images ? "host memcpy, all threads (llvmpipe: device memory is host memory)"
                            : "copy shader";
}

}  // namespace translume
