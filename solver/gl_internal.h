// SPDX-License-Identifier: MIT
// Internal to the gl backend (gl_*.cc): buffers, dispatch, and the multigrid solver's device
// state, shared by the solver and the inverse problem's objective. Includes GL headers.
#pragma once

#include <algorithm>
#include <array>
#include <initializer_list>
#include <memory>
#include <string>
#include <vector>

#include "solver/gl_api.h"
#include "solver/gl_shaders.h"
#include "solver/gl_solver.h"
#include "solver/multigrid_hierarchy.h"
#include "solver/status.h"

namespace translume {
namespace gl_internal {

using gl::api;

// How the shaders are specialised for the device (docs/gpu.md, "Shaders on llvmpipe"). Mesa
// llvmpipe (22.x) runs every shader-storage-buffer access as a scalar loop over the SIMD lanes
// with a bounds check per lane (~7 ns per access and invocation), an image-buffer access as one
// vector gather (~0.5 ns), and pays a fixed cost per invocation; a GPU wants plain buffer loads
// and many invocations. Chosen once from GL_RENDERER; TRANSLUME_GL_TUNING=llvmpipe|gpu forces one.
struct Tuning {
  // Arrays as image buffers (imageLoad / imageStore, TL_IMAGES in common.glsl) instead of
  // shader storage buffers.
  bool images = false;
  // One invocation per z-column of a level (kz = nz, common.glsl's Column) instead of one per
  // node (kz = 1), and grid-stride loops over at most `flat_groups` work groups per field for
  // the element-wise kernels (0: one invocation per element; FlatThreads adds groups where
  // LoopBudget needs them). TRANSLUME_GL_FLAT_GROUPS=N overrides flat_groups (N >= 1).
  bool columns = false;
  int flat_groups = 0;
  // Invocations per work group (common.glsl's TL_GROUP). TRANSLUME_GL_GROUP=N overrides it
  // (N >= 8).
  int group = 256;
  // Dots leave one partial sum per invocation, no shared-memory tree (TL_INVOCATION_SUMS).
  bool invocation_sums = false;
  // The coarse tail (tail.comp): the levels with at most this many nodes run their whole
  // V-cycle in one dispatch, one work group per field (0: never). TRANSLUME_GL_TAIL_NODES=N
  // overrides it.
  int64_t tail_nodes = 0;
  // Invocations of the tail's work group. TRANSLUME_GL_TAIL_GROUP=N overrides it.
  int tail_group = 256;
  // Fields per value in the V-cycles of a batch of three or more fields: 1, or 4 with four
  // fields' values interleaved as one vec4 per node (common.glsl's FIELDS4).
  int pack_fields = 1;
  // Single-field solves run the finest level in quarter rows (common.glsl's QUARTERS: four
  // nodes of a row per vec4). TRANSLUME_GL_QUARTERS=0|1 overrides it.
  bool quarters = false;
  // The line smoother's nodes per block (multigrid.glsl's MG_LINE_BLOCK; 1: node by node).
  // TRANSLUME_GL_LINE_BLOCK=N overrides it (1..16).
  int line_block = 1;
  // The line smoother by parallel cyclic reduction (multigrid.glsl's SmoothLinePcr: one
  // invocation per node, the column's serial chain log2 nz steps in shared memory) on the
  // levels whose columns fit a work group, instead of one invocation per column (SmoothLine).
  // Off by default until measured on a GPU (docs/gpu.md); TRANSLUME_GL_LINE_PCR=0|1 overrides.
  bool line_pcr = false;
  // Buffer::Zero and CopyFrom as dispatches of copy.comp instead of glClearBufferData and
  // glCopyBufferSubData (storage buffers only: not with `images`). On the H200 the renderer's
  // copies and clears left ~1.2 ms of a frame outside its dispatches (docs/gpu.md); a V-cycle
  // clears each coarse level's x. Off by default until measured on a GPU;
  // TRANSLUME_GL_SHADER_CLEAR=0|1 overrides.
  bool shader_clear = false;
  // glFlush after every flush_every dispatches (0: never). A driver may hold the commands
  // issued since the last wait (a read-back) until its buffer fills, so that the GPU idles
  // while the host issues them; a flush hands them over. Off by default until measured on a
  // GPU (docs/gpu.md); TRANSLUME_GL_FLUSH_EVERY=N overrides.
  int flush_every = 0;
};
const Tuning& GetTuning();

// A buffer's element type: its image format when the shaders read it as an image buffer.
enum class Elem { kFloat, kInt, kDouble, kVec4 };

class Buffer;
// Under Tuning::shader_clear: copies the first `bytes` bytes of *src to dst, or with src null
// zeroes them, with copy.comp and returns true; false (nothing done) where the GL's own call
// must do it (the tuning off, image buffers, sizes not in whole vec4s).
bool CopyOrZeroByShader(const Buffer* src, Buffer& dst, int64_t bytes);

// A shader storage buffer (and, under Tuning::images, the buffer texture that shaders bind as
// an image buffer).
class Buffer {
 public:
  Buffer() = default;
  Buffer(const Buffer&) = delete;
  ~Buffer() {
    if (tex_) api.DeleteTextures(1, &tex_);
    if (id_ && owner_) api.DeleteBuffers(1, &id_);
  }
  void Alloc(int64_t bytes, const void* data = nullptr, Elem elem = Elem::kFloat) {
    TL_CHECK(owner_);
    if (!id_) api.GenBuffers(1, &id_);
    bytes_ = std::max<int64_t>(bytes, 16);
    elem_ = elem;
    api.BindBuffer(GL_SHADER_STORAGE_BUFFER, id_);
    api.BufferData(GL_SHADER_STORAGE_BUFFER, bytes_, data, GL_DYNAMIC_DRAW);
    if (tex_) AttachTexture();
  }
  // Writes / reads `bytes` bytes at byte `offset` (a field of a batched buffer: f n elements).
  void Upload(const void* data, int64_t bytes, int64_t offset = 0) {
    api.BindBuffer(GL_SHADER_STORAGE_BUFFER, id_);
    api.BufferSubData(GL_SHADER_STORAGE_BUFFER, offset, bytes, data);
  }
  void Download(void* data, int64_t bytes, int64_t offset = 0) const {
    api.MemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT);
    api.BindBuffer(GL_SHADER_STORAGE_BUFFER, id_);
    api.GetBufferSubData(GL_SHADER_STORAGE_BUFFER, offset, bytes, data);
  }
  void Zero() {
    if (CopyOrZeroByShader(nullptr, *this, bytes_)) return;
    api.BindBuffer(GL_SHADER_STORAGE_BUFFER, id_);
    api.ClearBufferData(GL_SHADER_STORAGE_BUFFER, GL_R32F, GL_RED, GL_FLOAT, nullptr);
  }
  // Copies `bytes` bytes of src from byte src_offset to byte dst_offset of this buffer. (The
  // barrier: glCopyBufferSubData reads what shaders wrote into src only after one with
  // GL_BUFFER_UPDATE_BARRIER_BIT; later shaders see the copy without one.)
  void CopyFrom(const Buffer& src, int64_t bytes, int64_t src_offset = 0, int64_t dst_offset = 0) {
    if (src_offset == 0 && dst_offset == 0 && CopyOrZeroByShader(&src, *this, bytes)) return;
    api.MemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT);
    api.BindBuffer(GL_COPY_READ_BUFFER, src.id_);
    api.BindBuffer(GL_COPY_WRITE_BUFFER, id_);
    api.CopyBufferSubData(GL_COPY_READ_BUFFER, GL_COPY_WRITE_BUFFER, src_offset, dst_offset, bytes);
  }
  GLuint id() const { return id_; }
  // Makes this buffer a view of `of`'s storage that shaders read as `elem` (a float buffer as
  // vec4: four fields per node, common.glsl's FIELDS4). The view owns nothing and cannot be
  // allocated; make it again after `of` is reallocated.
  void ViewOf(const Buffer& of, Elem elem) {
    if (owner_ && id_) api.DeleteBuffers(1, &id_);
    owner_ = false;
    id_ = of.id_;
    bytes_ = of.bytes_;
    elem_ = elem;
    if (tex_) AttachTexture();
  }
  // Binds the buffer to image unit `unit` (read-write, in its element's format).
  void BindImage(GLuint unit) const {
    if (!tex_) {
      api.GenTextures(1, &tex_);
      AttachTexture();
    }
    api.BindImageTexture(unit, tex_, 0, GL_FALSE, 0, GL_READ_WRITE, Format());
  }

 private:
  GLenum Format() const {
    switch (elem_) {
      case Elem::kInt: return GL_R32I;
      case Elem::kDouble: return GL_RG32UI;  // unpacked with packDouble2x32 (common.glsl)
      case Elem::kVec4: return GL_RGBA32F;
      default: return GL_R32F;
    }
  }
  void AttachTexture() const {
    api.BindTexture(GL_TEXTURE_BUFFER, tex_);
    api.TexBuffer(GL_TEXTURE_BUFFER, Format(), id_);
    api.BindTexture(GL_TEXTURE_BUFFER, 0);
  }

  GLuint id_ = 0;
  mutable GLuint tex_ = 0;
  int64_t bytes_ = 0;
  Elem elem_ = Elem::kFloat;
  bool owner_ = true;
};

// The program of solver/shaders/NAME.comp, compiled once per `defines` (e.g. "#define X\n").
GLuint Program(const std::string& name, const std::string& defines = "");

// Binds `buffers` to bindings 0.., sets int uniforms at locations 0.., an optional float
// uniform, and dispatches `threads` threads (Tuning::group per group, tiled to stay under 65535
// groups per dimension), followed by a barrier. Returns the number of work groups.
int64_t Run(const char* name, std::initializer_list<const Buffer*> buffers,
            std::initializer_list<int> ints, int64_t threads, int float_location = -1,
            float float_value = 0, const char* defines = "");
// The same for `fields` fields at once: `threads` threads per field, work-group z = the field
// (common.glsl). Returns the number of work groups per field.
int64_t RunBatch(const char* name, std::initializer_list<const Buffer*> buffers,
                 std::initializer_list<int> ints, int64_t threads, int fields,
                 const char* defines = "");
// Compute dispatches issued by Run and RunBatch since the process started (for tests and the
// dispatch counts in docs/benchmarks.md).
int64_t DispatchCount();
// Work groups per field that Run and RunBatch dispatch for `threads` threads.
int64_t WorkGroups(int64_t threads);
// The most loop iterations one shader invocation may run, all its loops together (0: no
// limit): the context's GlInfo::loop_budget (llvmpipe's silent limit, solver/gl_context.h),
// whatever the tuning. The host keeps the coarse tail, whose one work group loops over whole
// levels, within it (Impl::PackLevels), the grid-stride loops too (FlatThreads, DotThreads),
// and refuses grids whose z-lines it cannot hold (GlMultigridSolver's constructor).
int64_t LoopBudget();
// Loop iterations of the budget that the host leaves unspent in every invocation it sizes:
// its counts of a shader's loops may miss a few.
constexpr int64_t kLoopSlack = 1024;
// The most inner-loop iterations one element of an element-wise kernel runs (a loop of k
// iterations counts k + 1): transfer.comp's restriction, three gathers of up to kMgTaps = 4
// taps, the nested 4 x 4 x 4 sums and the quarter rows' taps, about 130; cg_update.comp and
// pack.comp 5, the others none. gradient.comp counts its own (its loops over the fields).
constexpr int64_t kFlatLoopsPerElement = 160;
// Invocations of dot.comp for n elements, and the partial sums per field they leave.
int64_t DotThreads(int64_t n);
int64_t DotPartials(int64_t threads);
// Invocations for a grid-stride loop over n elements of `loops` inner-loop iterations each:
// Tuning::flat_groups work groups per field, or more where one invocation would otherwise
// loop past LoopBudget() (llvmpipe on grids of millions of nodes).
int64_t FlatThreads(int64_t n, int64_t loops = kFlatLoopsPerElement);
// Nodes per invocation of a column kernel on a level (common.glsl's kz), and its invocations.
int ColumnLength(const GridShape& s);
int64_t ColumnThreads(const GridShape& s);

// Slots of the per-field conjugate-gradient scalars; mirrors common.glsl's kCg* constants.
enum CgSlot { kCgRz, kCgPq, kCgRr, kCgRzNew, kCgBb, kCgActive, kCgIter, kCgTol2, kCgStride };

// One level of the hierarchy. Per node: geometry, kappa, mu, the stencil (cx, cy, cz, diag),
// the line factors (inv, luc) and rnorm; per field of a batch (Impl::Reserve): b, x, r. The
// transfers to the next level are packed for all levels (Impl::xfer_idx, xfer_w).
struct GLevel {
  MultigridLevel geo;
  GridShape s;
  int64_t n = 0;
  // diag: the full diagonal (line factors, coarsest inverse); sigma: its absorption and Robin
  // part alone, for the operator's difference form (assemble.comp, residual.comp).
  Buffer geometry, kappa, mu, cx, cy, cz, diag, sigma, inv, luc, b, x, r, rnorm;
  // b, x, r of a packed V-cycle (Impl::pack_fields 4): views of this level's b, x, r as vec4,
  // four fields per node, except on level 0, whose b holds the solve's right-hand sides: there
  // b4 views the CG vector q (free during a V-cycle).
  Buffer b4, x4, r4;
};

}  // namespace gl_internal

using gl_internal::Buffer;
using gl_internal::ColumnLength;
using gl_internal::ColumnThreads;
using gl_internal::Elem;
using gl_internal::FlatThreads;
using gl_internal::GetTuning;
using gl_internal::GLevel;
using gl_internal::Run;
using gl_internal::kCgActive;
using gl_internal::kCgBb;
using gl_internal::kCgIter;
using gl_internal::kCgPq;
using gl_internal::kCgRr;
using gl_internal::kCgRz;
using gl_internal::kCgRzNew;
using gl_internal::kCgStride;
using gl_internal::kCgTol2;
using gl_internal::RunBatch;
using gl_internal::DotPartials;
using gl_internal::DotThreads;
using gl_internal::WorkGroups;

struct GlMultigridSolver::Impl {
  MultigridOptions options;
  std::vector<std::unique_ptr<GLevel>> levels;
  // Per field of a batch (`capacity` fields, back to back): r, z, p, q (float), the host API's
  // iterate xd (double); per field: partial (dot.comp's partial sums), scal (the CG scalars,
  // kCgStride doubles) and hist (max_iterations recursive rr values).
  Buffer r, z, p, q, partial, scal, hist;
  Buffer xd;
  // A packed solve (Packed(nb)) runs on four fields per value throughout (common.glsl's
  // FIELDS4): r4, z4, p4, q4 are vec4 views of r, z, p, q (which then hold whole groups of
  // four), b_packed and x_packed the packed right-hand sides and iterates (x: four consecutive
  // doubles per node), packed from and unpacked into the caller's per-field b and x.
  Buffer r4, z4, p4, q4, b_packed, x_packed;
  Buffer coarse_inverse;  // dense inverse of the coarsest operator (when small enough)
  bool dense_coarse = false;
  int64_t n0 = 0;
  int coarse_sweeps = 8;
  int capacity = 0;
  int max_batch = 1;
  // Iterations between two read-backs of the per-field scalars (the convergence check; M x 8
  // doubles for the whole batch). 1: on llvmpipe a read-back costs nothing measurable while an
  // iteration past convergence costs a whole V-cycle for every field (bench recovery 12x10x5:
  // 31-34 s with 1, 36-38 s with 2; docs/benchmarks.md). On a GPU a read-back drains the queue
  // (tens of microseconds) against 1-2 ms per iteration, so 1 is the better bet there too.
  int check_every = 1;

  // Grows the per-field buffers to hold `fields` fields (contents are lost when they grow);
  // the level buffers and q hold whole groups of four where pack_fields is 4.
  void Reserve(int fields);
  // Sets pack_fields (1 or 4) and regrows the buffers for it.
  void SetPackFields(int k);
  // Whether a solve of nb fields runs packed, four fields per vec4 (FIELDS4): pack_fields
  // is 4 and nb >= 3 (fewer fields would leave llvmpipe's threads too few work groups).
  // The rounding up to whole groups must stay within max_batch (the buffers' limits).
  bool Packed(int nb) const { return pack_fields == 4 && nb >= 3 && (nb + 3) / 4 * 4 <= max_batch; }
  // The fields' slots of a packed batch of `fields` (whole groups of four, within max_batch;
  // else `fields`).
  int Slots4(int fields) const { return (fields + 3) / 4 * 4 <= max_batch ? (fields + 3) / 4 * 4 : fields; }
  // True while a packed solve or V-cycle runs (SolveDevice; Precondition and FullMultigrid
  // on per-field values): the dispatches then take FIELDS4 and one work group per four fields,
  // and the levels' b4, x4, r4.
  bool packed = false;
  // RunBatch for nb fields in the current layout: one work group z per field, or per four
  // fields with FIELDS4 defined while `packed`.
  int64_t RunFields(const char* name, std::initializer_list<const Buffer*> buffers,
                    std::initializer_list<int> ints, int64_t threads, int nb, const char* defines = "") {
    return RunBatch(name, buffers, ints, threads, packed ? (nb + 3) / 4 : nb,
                    ((packed ? "#define FIELDS4\n" : "") + std::string(defines)).c_str());
  }
  Buffer& LevelB(GLevel& L) { return packed ? L.b4 : L.b; }
  Buffer& LevelX(GLevel& L) { return packed ? L.x4 : L.x; }
  Buffer& LevelR(GLevel& L) { return packed || Quarter(L) ? L.r4 : L.r; }

  // Single-field solves in quarter rows (Tuning::quarters, common.glsl's QUARTERS): the finest
  // level's values and coefficients four nodes of a row per vec4, qw packed nodes per row, nq
  // packed nodes in all (cx_q .. sigma_q: its coefficients, packed for the solve). A
  // solve of one field runs quartered where the finest level is neither in the coarse tail nor
  // the coarsest: its CG vectors (r4 .. q4, b_packed, x_packed) and the finest level's V-cycle
  // work (smooth, residual, the transfers to and from level 1, which stays plain) on the
  // packed values.
  bool quarters = false;   // enabled: the tuning's, or SetQuarters
  bool quartered = false;  // true while a quartered solve runs
  int qw = 0;
  int64_t nq = 0;
  Buffer cx_q, cy_q, cz_q, inv_q, luc_q, sigma_q;
  // Whether cx_q .. sigma_q predate the last SetCoefficients: packed when a quartered solve
  // needs them (a recovery's batches never do).
  bool quarter_coefficients_stale = true;
  // (Not where the finest level is also the coarsest, solved by dense_solve on plain values.)
  bool Quartered(int nb) const { return quarters && nb == 1 && tail_level > 0 && levels.size() > 1; }
  bool Quarter(const GLevel& L) const { return quartered && &L == levels[0].get(); }
  void SetQuarters(bool on);
  // Packs the finest level's coefficients into cx_q .. sigma_q (allocated on first use);
  // while `quartered`.
  void QuarterCoefficients();
  // RunFields on level L's values: quartered on the one field where L is the finest level of
  // a quartered solve.
  int64_t RunOn(const GLevel& L, const char* name, std::initializer_list<const Buffer*> buffers,
                std::initializer_list<int> ints, int64_t threads, int nb, const char* defines = "") {
    if (Quarter(L))
      return RunBatch(name, buffers, ints, threads, 1,
                      ("#define FIELDS4\n#define QUARTERS\n" + std::string(defines)).c_str());
    return RunFields(name, buffers, ints, threads, nb, defines);
  }
  // Level L's shape and its smoother's and stencil's coefficients in the current layout.
  GridShape ShapeOf(const GLevel& L) const { return Quarter(L) ? GridShape{qw, L.s.ny, L.s.nz} : L.s; }
  struct Coefficients {
    const Buffer *cx, *cy, *cz, *inv, *luc, *sigma;
  };
  Coefficients CoefficientsOf(const GLevel& L) const {
    if (Quarter(L)) return {&cx_q, &cy_q, &cz_q, &inv_q, &luc_q, &sigma_q};
    return {&L.cx, &L.cy, &L.cz, &L.inv, &L.luc, &L.sigma};
  }
  // Values per field on the finest level in the current layout (the CG vectors' length).
  int64_t FinestCount() const { return quartered ? nq : n0; }
  // pack.comp, from the nb per-field values of `per_field` (n0 each) into the current layout's
  // vec4s (`packed4`), or the reverse: four fields to a vec4, or while `quartered` the one
  // field's quarter rows. With `doubles` both hold doubles (four consecutive ones per node
  // when packed).
  void Pack(const Buffer& per_field, Buffer& packed4, int nb, bool doubles = false);
  void Unpack(const Buffer& packed4, Buffer& per_field, int nb, bool doubles = false);
  void RunPack(const Buffer& per_field, const Buffer& packed4, int nb, bool doubles, bool unpack);

  // c = R f (level l to l + 1) and f += P c (level l + 1 to l) on nb fields: one dispatch
  // each (transfer.comp; level 0 quartered: from and to its quarter rows).
  void Restrict(size_t l, const Buffer& f, Buffer& c, int nb) {
    if (Quarter(*levels[l])) {
      RunBatch("transfer", {&f, &c, &xfer_idx, &xfer_w}, {int(l), 0, qw}, FlatThreads(levels[l + 1]->n), 1,
               "#define QUARTERS\n");
      return;
    }
    RunFields("transfer", {&f, &c, &xfer_idx, &xfer_w}, {int(l), 0}, FlatThreads(levels[l + 1]->n), nb);
  }
  void ProlongAdd(size_t l, const Buffer& c, Buffer& f, int nb) {
    if (Quarter(*levels[l])) {
      RunBatch("transfer", {&c, &f, &xfer_idx, &xfer_w}, {int(l), 1, qw}, FlatThreads(nq), 1,
               "#define QUARTERS\n#define PROLONG\n");
      return;
    }
    RunFields("transfer", {&c, &f, &xfer_idx, &xfer_w}, {int(l), 1}, FlatThreads(levels[l]->n), nb,
              "#define PROLONG\n");
  }

  // One half-sweep of colour `color`: SmoothLine, or SmoothLinePcr where PcrLength(L) > 0.
  void Smooth(GLevel& L, const Buffer& b, Buffer& x, int color, int nb) {
    const GridShape s = ShapeOf(L);
    const Coefficients c = CoefficientsOf(L);
    const int64_t columns = (s.nx + 1) / 2 * s.ny;
    if (const int P = PcrLength(L); P > 0) {
      RunOn(L, "smooth", {c.cx, c.cy, c.cz, &L.diag, c.luc, &b, &x}, {int(s.nx), int(s.ny), int(s.nz), color, P},
            columns * P, nb, "#define MG_LINE_PCR\n");
      return;
    }
    RunOn(L, "smooth", {c.cx, c.cy, c.cz, c.inv, c.luc, &b, &x}, {int(s.nx), int(s.ny), int(s.nz), color},
          columns, nb);
  }
  // Tuning::line_pcr unless a test changed it.
  bool line_pcr = false;
  // Invocations per column of SmoothLinePcr on level L: the power of two >= nz where line_pcr
  // is on, it divides the work group and L is not in quarter rows; else 0 (SmoothLine). (The
  // work group is the tuning's: Smooth never compiles smooth.comp with its own TL_GROUP, so
  // the shader's shared arrays and Tiling's groups both hold GetTuning().group invocations.
  // The coarse tail's levels never come here: tail.comp runs SmoothLine itself.)
  int PcrLength(const GLevel& L) const {
    if (!line_pcr || Quarter(L)) return 0;
    int P = 1;
    while (P < L.s.nz) P *= 2;
    return GetTuning().group % P == 0 ? P : 0;
  }

  // x_double (the CG iterate): x in double, the sums too (residual.comp).
  void Stencil(GLevel& L, const Buffer& x, const Buffer& b, Buffer& out, int mode, int nb,
               bool x_double = false) {
    const GridShape s = ShapeOf(L);
    const Coefficients c = CoefficientsOf(L);
    RunOn(L, "residual", {c.cx, c.cy, c.cz, c.sigma, &x, &b, &out},
          {int(s.nx), int(s.ny), int(s.nz), mode, ColumnLength(s)}, ColumnThreads(s), nb,
          x_double ? "#define X_DOUBLE\n" : "");
  }

  // One V-cycle x = B b on `nb` fields of level l. from_zero false: x holds an initial guess
  // (full multigrid). sweeps > 0: V(sweeps, sweeps) on this level and below, down to the
  // coarse tail, instead of the options' cycle. b and x in the current layout (`packed`).
  void VCycle(size_t l, const Buffer& b, Buffer& x, int nb, bool from_zero = true, int sweeps = 0);
  // z = B r on the finest level (one V-cycle): in a packed solve on its packed values, else on
  // per-field values, which it packs where Packed(nb) and the tail does not start on the
  // finest level (that tail packs its own fields).
  void Precondition(const Buffer& r, Buffer& z, int nb);
  // The cpu solver's full-multigrid pass (MultigridOptions::full_multigrid_start) for the
  // finest-level right-hand sides r: z = its approximate solution, in the same layout as
  // Precondition's r and z. Uses every level's b and x.
  // With a coarse tail, one V-cycle over the tail's levels stands in for the exact coarse solve
  // (the tail runs as one dispatch), so the pass differs from the per-level one there.
  void FullMultigrid(const Buffer& r, Buffer& z, int nb);
  void FullMultigridLevels(const Buffer& r, Buffer& z, int nb);  // in the current layout
  // run(b, x) on the finest level's r and z (Precondition's and FullMultigrid's layouts): as
  // they are, or packed into the finest level's b4 and x4 around it.
  template <typename F>
  void OnFinest(const Buffer& r, Buffer& z, int nb, F&& run) {
    if (packed || !Packed(nb) || tail_level == 0) {
      run(r, z);
      return;
    }
    GLevel& L = *levels[0];
    Pack(r, L.b4, nb);
    packed = true;
    run(L.b4, L.x4);
    packed = false;
    Unpack(L.x4, z, nb);
  }
  // The level the pass solves on before going up: the coarse tail's first or the coarsest.
  size_t FullMultigridTop() const { return std::min(tail_level, levels.size() - 1); }

  // The transfers between the levels, packed (multigrid.glsl's MG_TRANSFER): xfer_idx holds a
  // metadata row per level (with the tail's offsets), then gstart, gidx and lohi of every
  // level's three axes; xfer_w the weights gw and w.
  Buffer xfer_idx, xfer_w;
  // The coarse tail (tail.comp, docs/gpu.md): levels tail_level.. (the levels with at most
  // tail_nodes nodes, at least two of them) run their V-cycle in one dispatch; tail_level ==
  // levels.size(): no tail. tail_coef: their coefficients, packed; tail_work: tail_stride
  // values per field (for whole groups of four where packing is on); tail_work4: its view as
  // tail_stride vec4 per four fields (Packed batches).
  // pack_fields: Tuning::pack_fields unless SetPackFields changed it; tail_group:
  // Tuning::tail_group (tests may change it before a SetCoarseTail).
  int64_t tail_nodes = 0;
  int pack_fields = 1;
  int tail_group = 256;
  size_t tail_level = 0;
  Buffer tail_coef, tail_work, tail_work4;
  int64_t tail_stride = 0;
  std::vector<int64_t> tail_coef_offset;  // per level (tail levels only): its cx .. sigma in tail_coef
  bool coefficients_set = false;          // SetCoefficients ran (tail_coef can be filled)
  // Chooses the tail levels for tail_nodes and packs the transfers and the tail's layout
  // (tail_work is sized by Reserve, the coefficients copied by CopyTailCoefficients). The
  // tail starts on the first level with at most tail_nodes nodes where one invocation of
  // tail.comp stays within LoopBudget() (TailLoopIterations), with at least two levels.
  void PackLevels();
  // An upper bound of the loop iterations one invocation of tail.comp runs, all its loops
  // together (as llvmpipe counts them, LoopBudget()), when the tail starts on level
  // `first` with `tail_group` invocations per group: tail.comp's loops step by step, loops of
  // a constant count included (as if not unrolled), the CG_ITERATION steps added where
  // first == 0. About 40-80 iterations per node of the first level and tail_group invocations.
  int64_t TailLoopIterations(size_t first) const;
  void CopyTailCoefficients();
  // Whether SolveDevice runs each CG iteration of nb fields as one dispatch (tail.comp's
  // CG_ITERATION): the tail covers the whole hierarchy and the batch is Packed.
  bool CgIterationInTail(int nb) const;
  // Sizes tail_work and tail_work4 for `fields` fields.
  void AllocTailWork(int fields);
  // tail.comp on nb fields: x = B b from level tail_level down, four fields per work group
  // where Packed(nb) (b and x per field, or packed while `packed`).
  void Tail(const Buffer& b, Buffer& x, int nb);

  // a . b of every field (double) into scal[f kCgStride + slot]; Dot2 also a . c into slot + 1.
  // (In the current layout: `packed`.)
  void Dot(const Buffer& a, const Buffer& b, int slot, int nb) {
    const int64_t n = FinestCount();
    RunOn(*levels[0], "dot", {&a, &b, &partial}, {int(n), nb}, DotThreads(n), nb);
    const int64_t m = DotPartials(DotThreads(n));
    RunBatch("reduce", {&partial, &scal}, {int(m), slot, 1, kCgStride}, GetTuning().group, nb);
  }
  void Dot2(const Buffer& a, const Buffer& b, const Buffer& c, int slot, int nb) {
    const int64_t n = FinestCount();
    RunOn(*levels[0], "dot", {&a, &b, &partial, &c}, {int(n), nb}, DotThreads(n), nb, "#define PAIR\n");
    const int64_t m = DotPartials(DotThreads(n));
    RunBatch("reduce", {&partial, &scal}, {int(m), slot, 2, kCgStride}, GetTuning().group, nb);
  }
  // cg_update.comp in `mode` ("" or "#define DIRECTION\n" or "#define ADD\n"), current layout.
  void CgUpdate(std::initializer_list<const Buffer*> buffers, const char* mode, int nb) {
    const int64_t n = FinestCount();
    RunOn(*levels[0], "cg_update", buffers, {int(n), nb}, FlatThreads(n), nb, mode);
  }

  // Multigrid-PCG on `nb` fields at once, in lockstep (every dispatch serves all of them): b
  // (float) and the iterates x (double) hold nb fields of n0 values back to back; x holds the
  // initial guesses on entry. Coefficients must be set; nb <= max_batch. One summary per field;
  // `seconds` is the time of the whole batch. grouped: b and x are already in the packed
  // layout (Packed(nb) must hold; b a vec4 buffer of Slots4(nb) / 4 groups of n0, x four
  // consecutive doubles per node and group, padding fields 0), so that a caller who keeps its
  // fields packed (the gl objective) saves the pack and unpack passes around every solve.
  std::vector<SolveSummary> SolveDevice(const Buffer& b, Buffer& x, int nb, bool grouped = false);
};

}  // namespace translume
