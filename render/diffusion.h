// SPDX-License-Identifier: MIT
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "render/polygrid.h"

namespace translume {

// kappa (mm) and mu (1/mm) at every polygrid node, per RGB channel: kappa[c][node].
struct NodeMaterial {
  std::array<std::vector<float>, 3> kappa, mu;
};

// The polygrid diffusion equations (Wang et al. 2008, Equation (9)) in the relaxation form of
// Section 5.2 with phi' = kappa phi, written for every node n and channel c as
//   phi'_n <- (s_n + sum_k w_nk phi'_{nb_nk}) * inv_diag_n
// Interior node i: the conservative balance of SPEC section 3 on the Laplacian weights w_ji
// (Appendix B), sum_j w_ji kbar_ij (phi_j - phi_i) = mu_i phi_i with the face average
// kbar_ij = (kappa_i + kappa_j) / 2 (the paper's Equation (9) discretises Laplacian(kappa phi)
// instead, a different equation wherever kappa varies), so in phi':
//   w_k = w_ji kbar_ij kappa_i / kappa_j, s = 0,  1/inv_diag = mu_i + sum_j w_ji kbar_ij
// (homogeneous: w_k = kappa w_ji, 1/inv_diag = mu + kappa sum_j w_ji, the paper's row times kappa).
// Boundary node b linked to interior j, d = Polygrid::link_length (the link's extent along b's
// normal, so that (phi_f - phi_b) / d estimates -dphi/dn, phi_f at the link's foot v_b - d n_b):
// the Robin condition phi + 2 C kappa dphi/dn = q (Equation (9)) as a balance over the slab of
// depth d/2 that b owns along its link (vertex-centred finite volumes, the boundary half cells
// of SPEC section 3):
//   (phi_b - q_b) / (2 C) = kappa_b (phi_f - phi_b) / d - (d/2) mu_b phi_b
//                           + (d/2) sum_{k lateral} w_jk (phi'_k - phi'_j)
// phi_f = phi_j where the link is a normal; a leaning link (j has two or three boundary links)
// interpolates it, phi_f = (1 - sum_k a_k) phi_j + sum_k a_k phi_k over j's lateral neighbours k
// (a = Polygrid::foot_weights), which adds 2 C kappa_b^2 kappa_j a_k / kappa_k to w_k below and
// scales w_0's first term by 1 - sum_k a_k.
// the flux through the link, the slab's absorption, and its lateral diffusion taken from the
// four lateral terms of j's Laplacian (directions other than the link's axis). The paper's
// one-sided form keeps only the first term, which is first order in d; this is second order.
// Times 2 C kappa_b kappa_j d, with phi = phi' / kappa, W = sum_{k lateral} w_jk and
// A = 1 - sum_k a_k (1 for a normal link):
//   w_0 (node j) = 2 C kappa_b^2 A - C d^2 kappa_b kappa_j W,
//   w_1..4 (j's lateral neighbours k) = C d^2 kappa_b kappa_j w_jk + 2 C kappa_b^2 kappa_j a_k / kappa_k,
//   s = q_b kappa_b kappa_j d,  1/inv_diag = kappa_j d + 2 C kappa_b kappa_j + C d^2 mu_b kappa_j
// Where the lateral term would outweigh the link's (d^2 kappa_j W > 2 kappa_b A, so w_0 < 0: on a
// regular grid d^2 W is ~0.04, but a grid whose boundary nodes crowd together, such as the voxel
// polycube of a sharp-edged mesh, has W of 1/(tiny spacing)^2), the lateral weights are scaled
// down to make w_0 = 0: the row stays diagonally dominant and the relaxation convergent (it
// diverged to 1e12 on a tetrahedron), and the condition there falls back towards the paper's
// first-order form.
// Where the polygrid has Polygrid::stencil_weights, an interior row's face neighbours take the
// first six of them, and its edge-diagonal neighbours of positive weight follow as the row's
// extra entries (rows of equal width would make every row pay for the few sheared ones).
// Layouts: nb[n * 6 + k] (unused slots point at n with weight 0), w[(n * 3 + c) * 6 + k],
// s[n * 3 + c], inv_diag[n * 3 + c], and phi'[n * 3 + c]; extra entries e of row n for
// extra_start[n] <= e < extra_start[n + 1], at node extra_nb[e] with weight extra_w[e * 3 + c]
// (all three empty without the wide stencil).
struct JacobiSystem {
  int64_t size = 0;
  std::vector<int32_t> nb;
  std::vector<float> w, s, inv_diag;
  std::vector<int32_t> extra_start, extra_nb;
  std::vector<float> extra_w;
};

// q: incoming light at the boundary nodes, q[c][b - num_interior] (the SPEC's q: the Robin
// boundary phi + 2 C kappa dphi/dn = q).
using BoundaryLight = std::array<std::vector<float>, 3>;

JacobiSystem BuildJacobiSystem(const Polygrid& pg, const NodeMaterial& m, double C,
                               const BoundaryLight& q);

// Outgoing multiple-scattering radiance at the boundary nodes (Section 5.2, without the Fresnel
// factor, applied at shading): L_b = (phi'_b - q_b kappa_b) / (2 pi kappa_b) = (phi_b - q_b) / (2 pi)
// (q[c] empty: q = 0 in that channel).
BoundaryLight BoundaryRadiance(const Polygrid& pg, const NodeMaterial& m, const BoundaryLight& q,
                               const std::vector<float>& phi_prime);

// The radiance the renderer shades with: L_b = phi_b / (2 pi), BoundaryRadiance without
// subtracting q: the SPEC's (phi - q) / (2 pi) where unlit (q = 0). The paper's net-flux form
// is negative under the light (SPEC section 3), which would render lit regions black.
BoundaryLight ShadedRadiance(const Polygrid& pg, const NodeMaterial& m, const std::vector<float>& phi_prime);

// The reference solution for tests and the renderbench's error, in double: BiCGSTAB preconditioned by incomplete LU to a
// relative residual of 1e-12 (sparse LU if that fails); phi'[n * 3 + c] for the first
// `channels` channels (the others are left 0). With diagonal_preconditioner, BiCGSTAB first
// tries the diagonal (Jacobi) preconditioner, whose setup costs nothing: minutes less on
// polygrids of a million nodes, where the incomplete LU's takes most of the time.
std::vector<float> SolveReference(const JacobiSystem& system, int channels = 3,
                                  bool diagonal_preconditioner = false);

// Where the relaxation runs.
enum class DiffusionBackend { kCpu, kGl };

// Floats in a GL buffer of the gl backend: the buffer's name and the index of the first float.
// render/'s gl code (the passes and the relaxation, in the one headless context) hands a frame's
// q and radiance on through these, so that they stay on the GPU (Renderer, docs/render.md).
struct DeviceFloats {
  uint32_t buffer = 0;
  int64_t first = 0;
};
DiffusionBackend ParseDiffusionBackend(const std::string& text);

// The relaxation of a whole hierarchy on one backend, with the same arithmetic (float): the
// rows, prolongations and fluence stay where the backend keeps them (gl: GPU buffers), so per
// frame only the boundary light goes in and the finest level's fluence comes out. Levels are
// numbered finest first. Each step is JacobiSystem's update with its rows divided by their
// diagonal beforehand (RelaxationRows), and the source kept for the boundary rows only (the
// interior rows' is 0):
//   phi'_n <- sum_k a[n][k] phi'_{nb[n][k]} + (n boundary ? q_b g_b : 0)
// so a step reads 6 neighbour indices, 18 weights and 3 values per node, and per extra entry
// (JacobiSystem's) an index, 3 weights and 3 values (and the active list only when adaptive):
// nothing per interior node beyond the stencil.
// With Level::rho set, the steps of one Relax call are accelerated by Chebyshev's
// semi-iteration (Golub & Van Loan, Section 11.2.8; Varga 1962):
//   phi'_(k+1) = phi'_(k-1) + omega_(k+1) (J phi'_k - phi'_(k-1)),   J phi' = the step above,
// with the omega_k of ChebyshevSchedule (omega_1 = 1: the first step is Jacobi's), which also
// reads the previous iterate (3 values more per node). The fixed point is Jacobi's.
class HierarchyRelaxer {
 public:
  struct Level {
    int64_t size = 0;
    int64_t num_interior = 0;        // the boundary rows are [num_interior, size)
    std::vector<int32_t> nb;         // JacobiSystem::nb
    std::vector<float> a;            // a[(n * 3 + c) * 6 + k] = w * inv_diag (JacobiSystem's)
    std::vector<int32_t> extra_start, extra_nb;  // JacobiSystem's
    std::vector<float> extra_a;                  // extra_a[e * 3 + c] = extra_w * inv_diag
    std::vector<float> source_coef;  // g[b * 3 + c]: boundary row b's source per unit q, over its diagonal
    std::vector<int32_t> active;     // the nodes that adaptive relaxation updates
    Prolongation prolong;            // from the next coarser level (empty on the coarsest)
    // Per channel, the spectral radius of the step's iteration matrix (a) that Chebyshev's
    // semi-iteration assumes (JacobiSpectralRadii); 0: plain Jacobi steps.
    std::array<double, 3> rho{};
    // A frame's own calls (at most ChebyshevSchedule::kMaxCycle steps) end in Jacobi tails too,
    // as a coherent call's cycles do (ChebyshevSchedule's `repeated`): where the level's plain
    // sequence would grow modes off the real axis that the tails shrink (PolygridDiffusion
    // chooses per level).
    bool tails = false;
    // The finest level's only, for WriteShadedRadiance: 1 / (2 pi kappa_b) per boundary node and
    // channel [b * 3 + c] (ShadedRadiance's factor); empty on the other levels.
    std::vector<float> radiance_scale;
  };
  virtual ~HierarchyRelaxer() = default;
  virtual void Load(std::vector<Level> levels) = 0;
  virtual void SetSource(int level, const BoundaryLight& q) = 0;
  virtual void Zero(int level) = 0;     // phi' = 0
  virtual void Prolong(int level) = 0;  // phi'(level) = P phi'(level + 1)
  // `iterations` steps on the level's active nodes (adaptive) or all nodes; the others keep
  // their values. Jacobi's steps, or with Level::rho Chebyshev's, whose sequence starts afresh
  // in every call (ChebyshevSchedule; `repeated`: a frame-coherent call, continuing from the
  // last frame; it and Level::tails end the call's cycles in Jacobi tails). Zero and Prolong set every iterate the backend keeps.
  virtual void Relax(int level, bool adaptive, int iterations, bool repeated) = 0;
  // Rows [first_row, size) of the level's phi' into (*phi)[first_row * 3 ...]; phi holds
  // size * 3 values, the other rows are left as they are.
  virtual void Read(int level, int64_t first_row, std::vector<float>* phi) = 0;
  // gl only (the others CHECK): SetSource from q on the GPU, q_b,c at float q.first + b * 3 + c;
  // and ShadedRadiance of the finest level into a GPU buffer, channel-major as the shading pass
  // reads it: out[out.first + c * num_boundary + b] = max(0, phi'_b,c radiance_scale[b * 3 + c]).
  virtual void SetSource(int level, DeviceFloats q);
  virtual void WriteShadedRadiance(DeviceFloats out);
  static std::unique_ptr<HierarchyRelaxer> Create(DiffusionBackend backend);
};

// A level's relaxation rows (HierarchyRelaxer::Level: nb, a, source_coef; size and
// num_interior) from the polygrid and its material.
HierarchyRelaxer::Level RelaxationRows(const Polygrid& pg, const NodeMaterial& m, double C);

// Estimates of the spectral radius of the relaxation's iteration matrix a (nonnegative:
// RelaxationRows' weights are >= 0), per channel, from below: the smallest ratio (a x)_n / x_n
// (Collatz-Wielandt: rho >= min_n (a x)_n / x_n for any x > 0) after `iterations` steps of the
// power iteration x <- (x + a x) / 2 from x = 1 (halved with the identity so that a's
// eigenvalue -rho, which bipartite grids have, does not stall it); the three channels in one
// pass over the rows. An estimate below rho keeps Chebyshev's semi-iteration convergent for
// real eigenvalues within (-1, 1) (|T_k(lambda / r) / T_k(1 / r)| < 1 for every |lambda| < 1
// and r < 1), and it only slows the modes between the estimate and rho. (Real eigenvalues: a
// is similar to a symmetric matrix only approximately, as the boundary rows and distorted cells
// are not symmetric; a small sphere's spectrum is real, and at 9^3 nodes per edge its largest
// imaginary part is 6e-3, Diffusion.SpectralRadiusEstimateIsCloseFromBelow.) Rows of tiny
// weight sums pull the estimate towards 0, i.e. towards plain Jacobi steps.
std::array<double, 3> JacobiSpectralRadii(const HierarchyRelaxer::Level& level, int iterations = 50);

// What Chebyshev's steps with level.rho (per channel) leave of an error: `steps` of them (as
// ChebyshevSchedule runs them; `repeated`: in cycles with Jacobi tails, as a frame-coherent run)
// over every row from a fixed pseudo-random start in [-1, 1] without a source; the largest
// entry at the end, per channel (above 1: they grew it). (Adaptive steps run a subset of the
// rows; not checked apart.) The estimate above assumes a real spectrum; an iteration matrix
// whose eigenvalues lie far off the real axis (rows far from symmetric: a badly distorted grid,
// such as a tetrahedron's voxel polycube at 9^3 with the wide stencil, |Im| up to ~0.5) makes
// Chebyshev's polynomials grow there, by 1e4 in 100 steps, where Jacobi's steps still converge.
// PolygridDiffusion checks each level with 120 steps as a coherent run and with its own step
// count as one call (plain, or with the tails where the plain call grows and the tails leave
// less: Level::tails); where either check grows, it tries smaller radii (a wider ellipse), then
// Jacobi's steps.
std::array<double, 3> ChebyshevRemainder(const HierarchyRelaxer::Level& level, int steps = 120, bool repeated = true);

// The guard's three checks in one run (PolygridDiffusion): ChebyshevRemainder of `steps` as a
// coherent run, and of a frame's own call of `call_steps` (0: none) plain and with the tails.
// The calls are the coherent run's first steps as far as their weights agree (a plain call of
// up to 52 steps, the first cycle's sequence of 120; a tailed one up to its tails) and go on
// from a copy of its iterates where they part: the same numbers as three runs, in about
// steps + call_steps / 8 steps instead of steps + 2 call_steps.
struct ChebyshevRemainders {
  std::array<double, 3> coherent, plain, tailed;
};
ChebyshevRemainders ChebyshevCallRemainders(const HierarchyRelaxer::Level& level, int call_steps, int steps = 120);

// The over-relaxation weights of Chebyshev's semi-iteration for spectral radii rho (per
// channel): omega_1 = 1, omega_2 = 1 / (1 - rho^2 / 2), omega_(k+1) = 1 / (1 - rho^2 omega_k / 4)
// (omega_k decreases towards 2 / (1 + sqrt(1 - rho^2))); rho = 0 gives Jacobi (omega = 1).
//
// A relaxation call of at most kMaxCycle `steps` runs the sequence; a longer one, or one that
// is `repeated` (a frame-coherent frame, whose error carries over to the next), runs in cycles
// of at most kMaxCycle steps (as equal as the count allows), each of L steps ending in
// TailSteps(L) Jacobi steps (omega = 1) after L - TailSteps(L) steps of the sequence, which the
// next cycle starts afresh. Why: Chebyshev's steps shrink the error along eigenvalues z of the
// rows' matrix a inside the ellipse with foci -rho, rho through 1, and amplify it outside. a is
// not symmetric (the nodes' own Appendix-B weights, the boundary rows' links off the normal);
// on distorted polygrids some complex eigenvalues lie outside: the bunny's coarsest level at
// 9^3 under a homogeneous kappa 1 mm, mu 0.1 / mm has 8,
// the worst -0.146 +- 0.365i against an ellipse of semi-minor axis 0.31, growing ~10 % per step,
// so that long runs diverged and frame-coherent turntables, whose calls compound, brightened
// from frame to frame. Those modes sit on a few boundary nodes and their interior neighbours and
// have |z| 0.33-0.39, so Jacobi's steps shrink them fast: TailSteps(L) = ceil(L / 8) bounds a
// cycle's gain on them by 1.1^(L - J) 0.4^J, 0.1-0.8 for L <= 60. The smooth modes, which the
// acceleration is for, lose the J steps' share of it (2x the error after 30 steps), so a
// frame's calls of up to kMaxCycle steps keep the plain sequence where it shrinks the error
// (their gain on those modes is bounded once, not compounded), and end in the tails where
// those modes would grow more than the tails cost (HierarchyRelaxer::Level::tails: on the
// bunny with the wide stencil, whose finest level's plain 30 steps grew such modes 36-139-fold;
// docs/benchmarks.md, "Chebyshev's steps on the bunny", "Jacobi tails in a frame's calls").
class ChebyshevSchedule {
 public:
  static constexpr int kMaxCycle = 60;
  static int TailSteps(int cycle_length) { return (cycle_length + 7) / 8; }
  ChebyshevSchedule(const std::array<double, 3>& rho, int steps, bool repeated)
      : rho_(rho), steps_(steps), tails_(repeated || steps > kMaxCycle) {}
  std::array<float, 3> Next();  // the weights of the next step
  // Every weight 1: the step is Jacobi's and need not read the previous iterate.
  static bool IsJacobi(const std::array<float, 3>& omega) {
    return omega[0] == 1 && omega[1] == 1 && omega[2] == 1;
  }

 private:
  std::array<double, 3> rho_, omega_{};
  int steps_ = 0, done_ = 0;                  // the call's steps, those taken
  bool tails_ = false;                         // cycles with Jacobi tails, or one plain sequence
  int cycle_left_ = 0, run_left_ = 0, k_ = 0;  // in this cycle: steps left, sequence steps left and taken
};

enum class Relaxation { kJacobi, kChebyshev };
Relaxation ParseRelaxation(const std::string& text);  // "jacobi" or "chebyshev"; InputError otherwise

// The hierarchical, adaptive scheme of Section 5.3.
struct DiffusionOptions {
  DiffusionBackend backend = DiffusionBackend::kCpu;
  // Relaxation steps per level, COARSEST first; missing entries repeat the last one; with more
  // entries than levels the coarsest entries are dropped (the last is always the finest's).
  // (Jacobi's steps needed 200 / 100 / 100 and more; Chebyshev's 60 / 30 / 30 leave E 1.7e-4 on
  // the bunny at 17^3 under the procedural marble, 4.8e-4 under homogeneous 0.5, 0.05 (the
  // paper's Figure 15 allows 5e-3); docs/benchmarks.md, "Jacobi tails in a frame's calls".)
  std::vector<int> iterations = {60, 30, 30};
  // Adaptive depth per level, COARSEST first: after prolongation, only nodes within this many
  // layers of the boundary are updated on that level (the deeper ones stay at the coarse
  // solution, Fig. 8). -1 (or missing): all nodes. The coarsest level always updates all.
  std::vector<int> depth = {};
  // Start from the last frame's finest solution (skipping the coarse levels) when one exists.
  bool frame_coherence = false;
  // Frame-coherent frames run this many steps on the finest level.
  int coherent_iterations = 50;
  // The paper's Jacobi steps, or the same steps accelerated by Chebyshev's semi-iteration
  // (HierarchyRelaxer): on the bunny at 17^3 with 60 / 30 / 30 steps and the six weights, the
  // error against the converged solution falls from 1.5e-2 to 7.6e-5 (docs/benchmarks.md).
  Relaxation relaxation = Relaxation::kChebyshev;

  std::string Validate() const;
};

// Per-level material and light, finest level first (as BuildPolygridHierarchy returns).
class PolygridDiffusion {
 public:
  PolygridDiffusion(const std::vector<Polygrid>* levels, std::vector<NodeMaterial> materials,
                    double C, const DiffusionOptions& options);
  // Solves for phi' on every level, given q on each level's boundary nodes (finest first), and
  // returns the finest level's phi' (n * 3 + c); with boundary_only, only the boundary rows
  // are read back from the backend (the others are stale), which is all that shading needs.
  const std::vector<float>& Solve(const std::vector<BoundaryLight>& q, bool boundary_only = false);
  // The gl backend's frame without host round trips: Solve from q on the GPU (q[l]: level l's,
  // as HierarchyRelaxer::SetSource takes it), then the finest level's ShadedRadiance into
  // `radiance` on the GPU (WriteShadedRadiance's layout). Nothing is read back.
  void SolveOnDevice(const std::vector<DeviceFloats>& q, DeviceFloats radiance);
  const std::vector<NodeMaterial>& materials() const { return materials_; }
  int last_iterations() const { return last_iterations_; }
  // Channels of levels whose Chebyshev steps would grow with rho's estimate (ChebyshevRemainder
  // above 1, the frame's call checked as it runs: with the tails where Level::tails): they run
  // with rho scaled by 0.95, 0.9, 0.8 or 0.6, the first with which they shrink (reduced_radii),
  // or where none does, Jacobi's steps (jacobi_fallbacks, a subset).
  int reduced_radii() const { return reduced_radii_; }
  int jacobi_fallbacks() const { return jacobi_fallbacks_; }
  // Levels whose frame calls end in Jacobi tails (HierarchyRelaxer::Level::tails).
  int tailed_levels() const { return tailed_levels_; }
  void ResetCoherence() { have_previous_ = false; }

 private:
  // The hierarchy's steps (Section 5.3, or the frame-coherent ones) after set_source(level) for
  // each level it relaxes.
  template <typename SetSourceFn>
  void Relax(const SetSourceFn& set_source);

  const std::vector<Polygrid>* levels_;
  std::vector<NodeMaterial> materials_;
  double C_;
  DiffusionOptions options_;
  std::unique_ptr<HierarchyRelaxer> relaxer_;
  std::vector<int> depth_;       // adaptive depth per level (finest first), -1: all nodes
  std::vector<int> iterations_;  // relaxation steps per level (finest first)
  std::vector<float> phi_;
  bool have_previous_ = false;
  int last_iterations_ = 0;
  int reduced_radii_ = 0, jacobi_fallbacks_ = 0, tailed_levels_ = 0;
};

}  // namespace translume
