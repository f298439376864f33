// Screen-space part of the Gaussian rasteriser (methods/gaussians/rasterize.py, steps 2-6) as one C++ pass
// per pixel, forward and backward. The PyTorch path of rasterize.py is the twin the tests compare it with.
//
// Forward: every visible Gaussian covers the pixel centres inside its 3-sigma box (integer bounds computed
// with the same float32 operations as the PyTorch path). Row bands of at most max_pairs candidates are done
// one after the other (as the twin's bands: bounded memory). In a band, a counting pass gives every pixel a
// slot range for its candidates; the Gaussians, visited in depth order (a stable sort: ties by index, as the
// twin), write their pairs into those ranges, so each pixel's list is front to back without a sort and no
// pixel tests a Gaussian that does not cover it (a tiled walk measured 3x slower: its box tests
// mispredict). Per pair
// alpha = min(0.99, o exp(min(power, 0))) with
// power = -0.5 (A dx dx + C dy dy) - B dx dy (float32, in the twin's operation order; compiled without
// -ffast-math and with -ffp-contract=off so nothing is fused or reordered), drops alpha < 1/255, and
// composites front to back with the transmittance as a float64 running product of (1 - alpha) (the twin
// sums float32 log1p(-alpha) in float64 and exponentiates: the same to float32 rounding, two transcendental
// calls per pair fewer). A pixel stops at the first pair with T (1 - alpha) < t_min (3DGS's cut-off,
// the twin's prefix rule). Output rows per pixel: [sum w, sum w z, sum w c_0 .. c_{C-1}], w = alpha T.
// Only the contributing pairs are kept for the backward, pixel by pixel front to back: (Gaussian, o exp(power)
// before the 0.99 clamp, T as float32).
//
// Backward (one pass per pixel, back to front): with G_i = g . [1, z_i, c_i] the output gradient seen by
// pair i and S_i = sum_{k > i} w_k G_k, dL/dalpha_i = T_i G_i - S_i / (1 - alpha_i) (every later T_k holds
// the factor 1 - alpha_i); then through the clamps (a gradient passes where the clamped value is <= its
// bound, as torch's clamp_max), the exponential and the quadratic form to o, the conic (A, B, C) and the
// screen-space centre (u, v); d alpha / d o = exp(power) is read back as the stored o exp(power) / o (no
// exponential in the backward). The inputs and the float64 gradient sums are packed per Gaussian (one or two
// cache lines per pair instead of ten arrays: measured 16.5 -> 9.5 ms for 267k pairs on a loaded machine).
#include <torch/extension.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

namespace {

constexpr float ALPHA_MAX = 0.99f;
const float ALPHA_MIN = static_cast<float>(1.0 / 255.0);  // the twin compares float32 alpha with 1/255 cast to float32

struct Box {
  int x0, x1, y0, y1;  // inclusive pixel bounds; x0 > x1 or y0 > y1: empty
};

// The twin's _candidate_pairs bounds: ceil / floor of u0 -+ ext in float32, clipped to the image; a box
// entirely outside the image is empty.
inline Box pixel_box(float u0, float v0, float ex, float ey, int W, int H) {
  Box b{1, 0, 1, 0};
  if (!(u0 + ex >= 0.f) || u0 - ex > static_cast<float>(W - 1)) return b;
  if (!(v0 + ey >= 0.f) || v0 - ey > static_cast<float>(H - 1)) return b;
  const float x0 = std::max(0.f, std::ceil(u0 - ex)), x1 = std::min(static_cast<float>(W - 1), std::floor(u0 + ex));
  const float y0 = std::max(0.f, std::ceil(v0 - ey)), y1 = std::min(static_cast<float>(H - 1), std::floor(v0 + ey));
  if (!(x0 <= x1) || !(y0 <= y1)) return b;
  return Box{static_cast<int>(x0), static_cast<int>(x1), static_cast<int>(y0), static_cast<int>(y1)};
}

// power before its clamp at 0, in the twin's operation order
inline float pair_power(float A, float B, float C, float dx, float dy) {
  const float quad = A * dx * dx + C * dy * dy;
  return -0.5f * quad - B * dx * dy;
}

void check_float_rows(const torch::Tensor& t, int64_t rows, int64_t cols, const char* name) {
  TORCH_CHECK(t.device().is_cpu() && t.dtype() == torch::kFloat32 && t.is_contiguous(), name, ": contiguous float32 CPU tensor");
  TORCH_CHECK(cols == 0 ? (t.dim() == 1 && t.size(0) == rows) : (t.dim() == 2 && t.size(0) == rows && t.size(1) == cols), name,
              ": expected shape (", rows, cols == 0 ? "" : ", ", cols == 0 ? "" : std::to_string(cols), ")");
}

}  // namespace

// Returns (out (HW, 2 + C) float32, slot_gaussian (S,) int32, slot_alpha_raw (S,) float32, slot_T (S,) float32,
// pixel_start (HW,) int64,
// pixel_count (HW,) int32, stats (2,) int64 = [contributing pairs, candidate pairs]): pixel p's contributing
// pairs, front to back, are the slots pixel_start[p] .. pixel_start[p] + pixel_count[p] - 1.
std::vector<torch::Tensor> raster_forward(torch::Tensor means2d, torch::Tensor conics, torch::Tensor opacities, torch::Tensor depths,
                                          torch::Tensor colors, torch::Tensor extents, int64_t width, int64_t height, double t_min,
                                          int64_t max_pairs) {
  const int64_t M = means2d.size(0);
  TORCH_CHECK(colors.dim() == 2 && colors.size(0) == M && colors.size(1) >= 1, "colors: (M, C) with C >= 1");
  const int64_t C = colors.size(1);
  check_float_rows(means2d, M, 2, "means2d");
  check_float_rows(conics, M, 3, "conics");
  check_float_rows(opacities, M, 0, "opacities");
  check_float_rows(depths, M, 0, "depths");
  check_float_rows(colors, M, C, "colors");
  check_float_rows(extents, M, 2, "extents");
  TORCH_CHECK(M < (int64_t(1) << 31), "more than 2^31 Gaussians");
  TORCH_CHECK(width >= 1 && height >= 1 && width < (1 << 24) && height < (1 << 24), "image size out of range");
  TORCH_CHECK(t_min > 0.0 && max_pairs >= 1, "t_min and max_pairs must be positive");
  const int W = static_cast<int>(width), H = static_cast<int>(height);
  const int64_t HW = static_cast<int64_t>(W) * H;
  const float* m2 = means2d.data_ptr<float>();
  const float* con = conics.data_ptr<float>();
  const float* op = opacities.data_ptr<float>();
  const float* z = depths.data_ptr<float>();
  const float* col = colors.data_ptr<float>();
  const float* ext = extents.data_ptr<float>();

  // the Gaussians by increasing depth, ties by index (the twin's stable torch.sort; depths are finite here)
  std::vector<int64_t> ord(M);
  for (int64_t g = 0; g < M; ++g) ord[g] = g;
  std::stable_sort(ord.begin(), ord.end(), [z](int64_t i, int64_t j) { return z[i] < z[j]; });
  std::vector<Box> box(M);
  std::vector<int64_t> row_cand(H + 1, 0);  // candidates per image row
  for (int64_t g = 0; g < M; ++g) {
    box[g] = pixel_box(m2[2 * g], m2[2 * g + 1], ext[2 * g], ext[2 * g + 1], W, H);
    for (int y = box[g].y0; y <= box[g].y1; ++y) row_cand[y] += box[g].x1 - box[g].x0 + 1;
  }
  auto out = torch::zeros({HW, 2 + C}, torch::kFloat32);
  auto pix_start = torch::zeros({HW}, torch::kInt64);
  auto pix_count = torch::zeros({HW}, torch::kInt32);
  float* o = out.data_ptr<float>();
  int64_t* ps = pix_start.data_ptr<int64_t>();
  int32_t* pc = pix_count.data_ptr<int32_t>();
  std::vector<int32_t> keep_g;  // the contributing pairs, pixel by pixel front to back
  std::vector<float> keep_a, keep_T;
  std::vector<int32_t> n_slot;
  std::vector<int64_t> band_start;
  std::vector<int32_t> bg;
  std::vector<float> ba;
  int64_t n_cand = 0;
  // row bands of at most max_pairs candidates (at least one row): the candidate buffers stay bounded
  for (int y_lo = 0; y_lo < H;) {
    int y_hi = y_lo + 1;
    int64_t band_cand = row_cand[y_lo];
    while (y_hi < H && band_cand + row_cand[y_hi] <= max_pairs) band_cand += row_cand[y_hi++];
    n_cand += band_cand;
    const int64_t p_lo = static_cast<int64_t>(y_lo) * W, n_pix = static_cast<int64_t>(y_hi - y_lo) * W;
    // 1. candidates per pixel of the band (pixel centres inside a box), as offsets of each pixel's slot range
    n_slot.assign(n_pix, 0);
    for (int64_t g = 0; g < M; ++g) {
      const Box& b = box[g];
      for (int y = std::max(b.y0, y_lo); y <= std::min(b.y1, y_hi - 1); ++y) {
        int32_t* r = n_slot.data() + static_cast<int64_t>(y - y_lo) * W;
        for (int x = b.x0; x <= b.x1; ++x) ++r[x];
      }
    }
    band_start.assign(n_pix, 0);
    for (int64_t p = 1; p < n_pix; ++p) band_start[p] = band_start[p - 1] + n_slot[p - 1];
    // 2. each pixel's list in depth order: the Gaussian and o exp(power) (before the 0.99 clamp), for the
    // pairs with alpha >= 1/255
    bg.resize(band_cand);
    ba.resize(band_cand);
    std::fill(n_slot.begin(), n_slot.end(), 0);
    for (int64_t k = 0; k < M; ++k) {
      const int64_t g = ord[k];
      const Box& b = box[g];
      const float u0 = m2[2 * g], v0 = m2[2 * g + 1], A = con[3 * g], B = con[3 * g + 1], Cc = con[3 * g + 2], o_g = op[g];
      for (int y = std::max(b.y0, y_lo); y <= std::min(b.y1, y_hi - 1); ++y) {
        const float dy = static_cast<float>(y) - v0;
        for (int x = b.x0; x <= b.x1; ++x) {
          const float dx = static_cast<float>(x) - u0;
          const float a_raw = o_g * std::exp(std::min(pair_power(A, B, Cc, dx, dy), 0.f));
          if (!(std::min(a_raw, ALPHA_MAX) >= ALPHA_MIN)) continue;
          const int64_t p = static_cast<int64_t>(y - y_lo) * W + x;
          const int64_t slot = band_start[p] + n_slot[p]++;
          bg[slot] = static_cast<int32_t>(g);
          ba[slot] = a_raw;
        }
      }
    }
    // 3. front-to-back compositing; the contributing pairs (and T as float32) are kept for the backward
    for (int64_t p = 0; p < n_pix; ++p) {
      const int64_t pix = p_lo + p;
      float* row = o + pix * (2 + C);
      ps[pix] = static_cast<int64_t>(keep_g.size());
      double T = 1.0;  // transmittance in front of the next pair
      int32_t count = 0;
      for (int32_t j = 0; j < n_slot[p]; ++j) {
        const int64_t slot = band_start[p] + j;
        const int32_t g = bg[slot];
        const float alpha = std::min(ba[slot], ALPHA_MAX);
        const double after = T * (1.0 - static_cast<double>(alpha));
        if (!(after >= t_min)) break;  // T only falls further: every later pair of this pixel is cut off too
        const float Tf = static_cast<float>(T);
        const float w = alpha * Tf;
        row[0] += w;
        row[1] += w * z[g];
        for (int64_t c = 0; c < C; ++c) row[2 + c] += w * col[g * C + c];
        keep_g.push_back(g);
        keep_a.push_back(ba[slot]);
        keep_T.push_back(Tf);
        ++count;
        T = after;
      }
      pc[pix] = count;
    }
    y_lo = y_hi;
  }
  const int64_t P = static_cast<int64_t>(keep_g.size());
  auto slot_g = torch::empty({P}, torch::kInt32);
  auto slot_a = torch::empty({P}, torch::kFloat32);
  auto slot_T = torch::empty({P}, torch::kFloat32);
  std::copy(keep_g.begin(), keep_g.end(), slot_g.data_ptr<int32_t>());
  std::copy(keep_a.begin(), keep_a.end(), slot_a.data_ptr<float>());
  std::copy(keep_T.begin(), keep_T.end(), slot_T.data_ptr<float>());
  auto stats = torch::tensor({P, n_cand}, torch::kInt64);
  return {out, slot_g, slot_a, slot_T, pix_start, pix_count, stats};
}

// Returns the gradients of (means2d (M, 2), conics (M, 3), opacities (M,), depths (M,), colors (M, C)).
std::vector<torch::Tensor> raster_backward(torch::Tensor grad_out, torch::Tensor means2d, torch::Tensor conics, torch::Tensor opacities,
                                           torch::Tensor depths, torch::Tensor colors, torch::Tensor slot_g, torch::Tensor slot_a,
                                           torch::Tensor slot_T, torch::Tensor pix_start, torch::Tensor pix_count, int64_t width) {
  const int64_t M = means2d.size(0);
  const int64_t C = colors.size(1);
  const int64_t HW = pix_start.size(0);
  const int W = static_cast<int>(width);
  const float* go = grad_out.data_ptr<float>();
  const int32_t* sg = slot_g.data_ptr<int32_t>();
  const float* sa = slot_a.data_ptr<float>();
  const float* sT = slot_T.data_ptr<float>();
  const int64_t* ps = pix_start.data_ptr<int64_t>();
  const int32_t* pc = pix_count.data_ptr<int32_t>();
  // per Gaussian, packed so that a pair touches one or two cache lines: [u, v, A, B, C, o, z, c_0 .. c_{C-1}]
  const int64_t D = 7 + C;
  std::vector<float> par(M * D);
  {
    const float* m2 = means2d.data_ptr<float>();
    const float* con = conics.data_ptr<float>();
    const float* op = opacities.data_ptr<float>();
    const float* z = depths.data_ptr<float>();
    const float* col = colors.data_ptr<float>();
    for (int64_t g = 0; g < M; ++g) {
      float* p = par.data() + g * D;
      p[0] = m2[2 * g]; p[1] = m2[2 * g + 1];
      p[2] = con[3 * g]; p[3] = con[3 * g + 1]; p[4] = con[3 * g + 2];
      p[5] = op[g]; p[6] = z[g];
      for (int64_t c = 0; c < C; ++c) p[7 + c] = col[g * C + c];
    }
  }
  std::vector<double> acc(M * D, 0.0);  // the gradients, same layout
  for (int64_t pix = 0; pix < HW; ++pix) {
    const int32_t n = pc[pix];
    if (n == 0) continue;
    const float* g_row = go + pix * (2 + C);
    const float px = static_cast<float>(pix % W), py = static_cast<float>(pix / W);
    double S = 0.0;  // sum over the pairs behind this one of w_k G_k
    for (int32_t j = n - 1; j >= 0; --j) {
      const int64_t k = ps[pix] + j;
      const int32_t g = sg[k];
      const float* p = par.data() + g * D;
      double* d = acc.data() + g * D;
      const double T = sT[k];
      const float a_raw = sa[k];
      const float alpha = std::min(a_raw, ALPHA_MAX);
      const double w = static_cast<double>(alpha) * T;
      double G = g_row[0] + static_cast<double>(g_row[1]) * p[6];
      for (int64_t c = 0; c < C; ++c) G += static_cast<double>(g_row[2 + c]) * p[7 + c];
      d[6] += static_cast<double>(g_row[1]) * w;
      for (int64_t c = 0; c < C; ++c) d[7 + c] += static_cast<double>(g_row[2 + c]) * w;
      const double d_alpha = T * G - S / (1.0 - static_cast<double>(alpha));
      S += w * G;
      if (!(a_raw <= ALPHA_MAX)) continue;  // clamped at 0.99: no gradient to o or the power
      d[5] += d_alpha * (static_cast<double>(a_raw) / p[5]);  // d alpha / d o = exp(power) = a_raw / o (o >= 1/255 here)
      const float dx = px - p[0];
      const float dy = py - p[1];
      const float A = p[2], B = p[3], Cc = p[4];
      if (!(pair_power(A, B, Cc, dx, dy) <= 0.f)) continue;  // power clamped at 0
      const double d_power = d_alpha * a_raw;
      d[2] += d_power * (-0.5 * dx * dx);
      d[3] += d_power * (-static_cast<double>(dx) * dy);
      d[4] += d_power * (-0.5 * dy * dy);
      // power depends on dx = px - u and dy = py - v
      d[0] += d_power * (static_cast<double>(A) * dx + static_cast<double>(B) * dy);
      d[1] += d_power * (static_cast<double>(B) * dx + static_cast<double>(Cc) * dy);
    }
  }
  auto d_m2 = torch::empty({M, 2}, torch::kFloat32);
  auto d_con = torch::empty({M, 3}, torch::kFloat32);
  auto d_op = torch::empty({M}, torch::kFloat32);
  auto d_z = torch::empty({M}, torch::kFloat32);
  auto d_col = torch::empty({M, C}, torch::kFloat32);
  float *o2 = d_m2.data_ptr<float>(), *oc = d_con.data_ptr<float>(), *oo = d_op.data_ptr<float>(), *oz = d_z.data_ptr<float>(),
        *ocol = d_col.data_ptr<float>();
  for (int64_t g = 0; g < M; ++g) {
    const double* d = acc.data() + g * D;
    o2[2 * g] = static_cast<float>(d[0]); o2[2 * g + 1] = static_cast<float>(d[1]);
    for (int i = 0; i < 3; ++i) oc[3 * g + i] = static_cast<float>(d[2 + i]);
    oo[g] = static_cast<float>(d[5]);
    oz[g] = static_cast<float>(d[6]);
    for (int64_t c = 0; c < C; ++c) ocol[g * C + c] = static_cast<float>(d[7 + c]);
  }
  return {d_m2, d_con, d_op, d_z, d_col};
}

// ------------------------------------------------------------------------------------------------ projection
// EWA projection of the visible Gaussians (rasterize.py, project_gaussians: step 1), in float64 like the twin,
// with its hand-derived backward. cam: [R (9, row-major), t (3), fx, fy, cx, cy, lim_xn, lim_xp, lim_yn,
// lim_yp, eps2d, max_scale] as float64.
namespace {

struct Proj {
  double pc[3];     // camera-frame centre
  double q[4];      // normalised quaternion (w, x, y, z); identity for |q| <= 1e-12
  double qn;        // |q|
  double s[3];      // clamped scales
  double Rr[9];     // R_cw R(q)
  double Mx[9];     // R_cw R(q) S
  double cov[9];    // Mx Mx^T
  double tx, ty;    // z * clamped x/z, y/z
  bool clx, cly;    // the slope clamps are active
  double J[6];      // 2 x 3
  double a, b, c, det;
  bool det_clamped;
};

inline void project_one(const float* m, const float* qr, const float* sc, const double* cam, Proj& P) {
  const double* R = cam;
  const double* t = cam + 9;
  const double fx = cam[12], fy = cam[13];
  for (int i = 0; i < 3; ++i) P.pc[i] = R[3 * i] * m[0] + R[3 * i + 1] * m[1] + R[3 * i + 2] * m[2] + t[i];
  const double qw = qr[0], qx = qr[1], qy = qr[2], qz = qr[3];
  P.qn = std::sqrt(qw * qw + qx * qx + qy * qy + qz * qz);
  if (P.qn > 1e-12) {
    P.q[0] = qw / P.qn; P.q[1] = qx / P.qn; P.q[2] = qy / P.qn; P.q[3] = qz / P.qn;
  } else {
    P.q[0] = 1.0; P.q[1] = P.q[2] = P.q[3] = 0.0;
  }
  const double w = P.q[0], x = P.q[1], y = P.q[2], z = P.q[3];
  const double r[9] = {1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
                       2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
                       2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)};
  for (int j = 0; j < 3; ++j) P.s[j] = std::min(std::max(static_cast<double>(sc[j]), 0.0), cam[21]);
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      P.Rr[3 * i + j] = R[3 * i] * r[j] + R[3 * i + 1] * r[3 + j] + R[3 * i + 2] * r[6 + j];
      P.Mx[3 * i + j] = P.Rr[3 * i + j] * P.s[j];
    }
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) P.cov[3 * i + j] = P.Mx[3 * i] * P.Mx[3 * j] + P.Mx[3 * i + 1] * P.Mx[3 * j + 1] + P.Mx[3 * i + 2] * P.Mx[3 * j + 2];
  const double zc = P.pc[2];
  const double sx = P.pc[0] / zc, sy = P.pc[1] / zc;
  P.clx = !(sx >= -cam[16] && sx <= cam[17]);
  P.cly = !(sy >= -cam[18] && sy <= cam[19]);
  P.tx = zc * std::min(std::max(sx, -cam[16]), cam[17]);
  P.ty = zc * std::min(std::max(sy, -cam[18]), cam[19]);
  const double J[6] = {fx / zc, 0.0, -fx * P.tx / (zc * zc), 0.0, fy / zc, -fy * P.ty / (zc * zc)};
  std::copy(J, J + 6, P.J);
  double JS[6];  // J cov
  for (int i = 0; i < 2; ++i)
    for (int j = 0; j < 3; ++j) JS[3 * i + j] = J[3 * i] * P.cov[j] + J[3 * i + 1] * P.cov[3 + j] + J[3 * i + 2] * P.cov[6 + j];
  P.a = JS[0] * J[0] + JS[1] * J[1] + JS[2] * J[2] + cam[20];
  P.b = JS[0] * J[3] + JS[1] * J[4] + JS[2] * J[5];
  P.c = JS[3] * J[3] + JS[4] * J[4] + JS[5] * J[5] + cam[20];
  const double det = P.a * P.c - P.b * P.b;
  P.det_clamped = !(det >= 1e-12);
  P.det = P.det_clamped ? 1e-12 : det;
}

}  // namespace

// Returns (means2d (M, 2), conics (M, 3), depths (M,), extents (M, 2) float64) of the M visible Gaussians.
void check_projection_inputs(const torch::Tensor& means, const torch::Tensor& quats, const torch::Tensor& scales, const torch::Tensor& cam) {
  const int64_t M = means.size(0);
  check_float_rows(means, M, 3, "means");
  check_float_rows(quats, M, 4, "quats");
  check_float_rows(scales, M, 3, "scales");
  TORCH_CHECK(cam.device().is_cpu() && cam.dtype() == torch::kFloat64 && cam.is_contiguous() && cam.numel() == 22,
              "cam: 22 contiguous float64 values");
}

std::vector<torch::Tensor> project_forward(torch::Tensor means, torch::Tensor quats, torch::Tensor scales, torch::Tensor cam) {
  check_projection_inputs(means, quats, scales, cam);
  const int64_t M = means.size(0);
  const float* m = means.data_ptr<float>();
  const float* q = quats.data_ptr<float>();
  const float* s = scales.data_ptr<float>();
  const double* cm = cam.data_ptr<double>();
  auto m2d = torch::empty({M, 2}, torch::kFloat32);
  auto con = torch::empty({M, 3}, torch::kFloat32);
  auto dep = torch::empty({M}, torch::kFloat32);
  auto ext = torch::empty({M, 2}, torch::kFloat64);
  float* o2 = m2d.data_ptr<float>();
  float* oc = con.data_ptr<float>();
  float* oz = dep.data_ptr<float>();
  double* oe = ext.data_ptr<double>();
  for (int64_t g = 0; g < M; ++g) {
    Proj P;
    project_one(m + 3 * g, q + 4 * g, s + 3 * g, cm, P);
    const double zc = P.pc[2];
    o2[2 * g] = static_cast<float>(cm[12] * P.pc[0] / zc + cm[14]);
    o2[2 * g + 1] = static_cast<float>(cm[13] * P.pc[1] / zc + cm[15]);
    oc[3 * g] = static_cast<float>(P.c / P.det);
    oc[3 * g + 1] = static_cast<float>(-P.b / P.det);
    oc[3 * g + 2] = static_cast<float>(P.a / P.det);
    oz[g] = static_cast<float>(zc);
    oe[2 * g] = 3.0 * std::sqrt(P.a);
    oe[2 * g + 1] = 3.0 * std::sqrt(P.c);
  }
  return {m2d, con, dep, ext};
}

// Gradients of (means (M, 3), quats (M, 4), scales (M, 3)) from those of (means2d, conics, depths).
std::vector<torch::Tensor> project_backward(torch::Tensor g_m2d, torch::Tensor g_con, torch::Tensor g_dep, torch::Tensor means,
                                            torch::Tensor quats, torch::Tensor scales, torch::Tensor cam) {
  check_projection_inputs(means, quats, scales, cam);
  const int64_t M = means.size(0);
  check_float_rows(g_m2d, M, 2, "grad means2d");
  check_float_rows(g_con, M, 3, "grad conics");
  check_float_rows(g_dep, M, 0, "grad depths");
  const float* m = means.data_ptr<float>();
  const float* q = quats.data_ptr<float>();
  const float* s = scales.data_ptr<float>();
  const double* cm = cam.data_ptr<double>();
  const float* gm = g_m2d.data_ptr<float>();
  const float* gc = g_con.data_ptr<float>();
  const float* gd = g_dep.data_ptr<float>();
  auto d_means = torch::empty({M, 3}, torch::kFloat32);
  auto d_quats = torch::empty({M, 4}, torch::kFloat32);
  auto d_scales = torch::empty({M, 3}, torch::kFloat32);
  float* om = d_means.data_ptr<float>();
  float* oq = d_quats.data_ptr<float>();
  float* os = d_scales.data_ptr<float>();
  const double* R = cm;
  const double fx = cm[12], fy = cm[13];
  for (int64_t g = 0; g < M; ++g) {
    Proj P;
    project_one(m + 3 * g, q + 4 * g, s + 3 * g, cm, P);
    const double x = P.pc[0], y = P.pc[1], zc = P.pc[2];
    double dpc[3] = {0.0, 0.0, static_cast<double>(gd[g])};
    // u = fx x / z + cx, v = fy y / z + cy
    const double gu = gm[2 * g], gv = gm[2 * g + 1];
    dpc[0] += gu * fx / zc;
    dpc[1] += gv * fy / zc;
    dpc[2] += -gu * fx * x / (zc * zc) - gv * fy * y / (zc * zc);
    // conic = (c, -b, a) / det
    const double gA = gc[3 * g], gB = gc[3 * g + 1], gC = gc[3 * g + 2];
    const double det = P.det;
    const double d_det = P.det_clamped ? 0.0 : -(gA * P.c - gB * P.b + gC * P.a) / (det * det);
    const double da = gC / det + d_det * P.c;
    const double db = -gB / det - 2.0 * d_det * P.b;
    const double dc = gA / det + d_det * P.a;
    // cov2d = J cov J^T; a, b, c read entries (0,0), (0,1), (1,1): G2 = [[da, db], [0, dc]]
    const double G2s[4] = {2.0 * da, db, db, 2.0 * dc};  // G2 + G2^T
    const double* J = P.J;
    double GJ[6];   // (G2 + G2^T) J cov: the gradient of J
    double GJ0[6];  // (G2 + G2^T) J
    for (int i = 0; i < 2; ++i)
      for (int j = 0; j < 3; ++j) GJ0[3 * i + j] = G2s[2 * i] * J[j] + G2s[2 * i + 1] * J[3 + j];
    for (int i = 0; i < 2; ++i)
      for (int j = 0; j < 3; ++j) GJ[3 * i + j] = GJ0[3 * i] * P.cov[j] + GJ0[3 * i + 1] * P.cov[3 + j] + GJ0[3 * i + 2] * P.cov[6 + j];
    // gradient of cov: J^T G2 J (not symmetric; the product cov = Mx Mx^T below takes both G and G^T)
    double Gcov[9];
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j)
        Gcov[3 * i + j] = J[i] * (da * J[j] + db * J[3 + j]) + J[3 + i] * dc * J[3 + j];
    // J = [[fx/z, 0, -fx tx/z^2], [0, fy/z, -fy ty/z^2]]
    const double z2 = zc * zc, z3 = z2 * zc;
    dpc[2] += GJ[0] * (-fx / z2) + GJ[2] * (2.0 * fx * P.tx / z3) + GJ[4] * (-fy / z2) + GJ[5] * (2.0 * fy * P.ty / z3);
    const double dtx = GJ[2] * (-fx / z2), dty = GJ[5] * (-fy / z2);
    // tx = z * clamp(x / z): unclamped dtx/dx = 1 (and 0 in z); clamped dtx/dz = the bound
    if (P.clx) dpc[2] += dtx * (P.tx / zc); else dpc[0] += dtx;
    if (P.cly) dpc[2] += dty * (P.ty / zc); else dpc[1] += dty;
    // cov = Mx Mx^T: dMx = (Gcov + Gcov^T) Mx
    double GM[9];
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) {
        double acc = 0.0;
        for (int k = 0; k < 3; ++k) acc += (Gcov[3 * i + k] + Gcov[3 * k + i]) * P.Mx[3 * k + j];
        GM[3 * i + j] = acc;
      }
    // Mx = R rot diag(s)
    double Grot[9];
    for (int k = 0; k < 3; ++k)
      for (int j = 0; j < 3; ++j) Grot[3 * k + j] = (R[k] * GM[j] + R[3 + k] * GM[3 + j] + R[6 + k] * GM[6 + j]) * P.s[j];
    for (int j = 0; j < 3; ++j) {
      const double sj = s[3 * g + j];
      double acc = 0.0;
      if (sj >= 0.0 && sj <= cm[21])  // the clamp to [0, max_scale] passes the gradient inside (bounds included)
        for (int i = 0; i < 3; ++i) acc += GM[3 * i + j] * P.Rr[3 * i + j];
      os[3 * g + j] = static_cast<float>(acc);
    }
    // rot(q) for the normalised q
    const double w = P.q[0], qx = P.q[1], qy = P.q[2], qz = P.q[3];
    const double* G = Grot;
    const double dq[4] = {
        2 * (-G[1] * qz + G[2] * qy + G[3] * qz - G[5] * qx - G[6] * qy + G[7] * qx),
        2 * (G[1] * qy + G[2] * qz + G[3] * qy - 2 * G[4] * qx - G[5] * w + G[6] * qz + G[7] * w - 2 * G[8] * qx),
        2 * (-2 * G[0] * qy + G[1] * qx + G[2] * w + G[3] * qx + G[5] * qz - G[6] * w + G[7] * qz - 2 * G[8] * qy),
        2 * (-2 * G[0] * qz - G[1] * w + G[2] * qx + G[3] * w - 2 * G[4] * qz + G[5] * qy + G[6] * qx + G[7] * qy)};
    if (P.qn > 1e-12) {
      const double dot = dq[0] * w + dq[1] * qx + dq[2] * qy + dq[3] * qz;
      for (int k = 0; k < 4; ++k) oq[4 * g + k] = static_cast<float>((dq[k] - P.q[k] * dot) / P.qn);
    } else {
      for (int k = 0; k < 4; ++k) oq[4 * g + k] = 0.f;
    }
    // pc = R m + t
    for (int k = 0; k < 3; ++k) om[3 * g + k] = static_cast<float>(R[k] * dpc[0] + R[3 + k] * dpc[1] + R[6 + k] * dpc[2]);
  }
  return {d_means, d_quats, d_scales};
}

PYBIND11_MODULE(TORCH_EXTENSION_NAME, m) {
  m.def("raster_forward", &raster_forward, "Gaussian rasteriser, screen-space forward (per-pixel compositing)");
  m.def("raster_backward", &raster_backward, "Gaussian rasteriser, screen-space backward");
  m.def("project_forward", &project_forward, "EWA projection of the visible Gaussians (float64 inside)");
  m.def("project_backward", &project_backward, "EWA projection, backward");
}
