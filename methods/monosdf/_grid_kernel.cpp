// Multi-resolution grid: trilinear features + analytic spatial Jacobian (forward) and the scatter-add
// table gradient (backward). Same contract as grid.py::interpolate_reference (the tests compare them).
// x: (P, 3) float32 in [-1, 1]; meta: (L, 4) int64 rows [resolution, offset, size, hashed];
// table: (rows, F) float32. feat: (P, L*F); jac: (P, 3, L*F) = d feat / d x.
#include <torch/extension.h>
#include <cmath>
#include <cstdint>
#include <vector>
#include <omp.h>

namespace {

inline int64_t corner_index(int64_t vx, int64_t vy, int64_t vz, int64_t res, int64_t size, bool hashed) {
    if (hashed) {
        uint64_t h = (uint64_t)vx * 1ull ^ (uint64_t)vy * 2654435761ull ^ (uint64_t)vz * 805459861ull;
        return (int64_t)(h & (uint64_t)(size - 1));
    }
    const int64_t n = res + 1;
    return vx + n * (vy + n * vz);
}

struct Cell {
    int64_t idx[8];
    float w[8];
    float dw[8][3];
};

inline void cell_for(const float* xp, int64_t res, int64_t offset, int64_t size, bool hashed, bool need_dw, Cell& c) {
    int64_t i0[3];
    float f[3];
    for (int d = 0; d < 3; ++d) {
        float xd = xp[d] < -1.f ? -1.f : (xp[d] > 1.f ? 1.f : xp[d]);
        float pos = (xd + 1.f) * 0.5f * (float)res;
        float fl = std::floor(pos);
        if (fl < 0.f) fl = 0.f;
        if (fl > (float)(res - 1)) fl = (float)(res - 1);
        i0[d] = (int64_t)fl;
        f[d] = pos - fl;
    }
    const float half_res = 0.5f * (float)res;
    for (int k = 0; k < 8; ++k) {
        const int cx = k & 1, cy = (k >> 1) & 1, cz = (k >> 2) & 1;
        const float wx = cx ? f[0] : 1.f - f[0];
        const float wy = cy ? f[1] : 1.f - f[1];
        const float wz = cz ? f[2] : 1.f - f[2];
        c.idx[k] = offset + corner_index(i0[0] + cx, i0[1] + cy, i0[2] + cz, res, size, hashed);
        c.w[k] = wx * wy * wz;
        if (need_dw) {
            c.dw[k][0] = (cx ? 1.f : -1.f) * wy * wz * half_res;
            c.dw[k][1] = wx * (cy ? 1.f : -1.f) * wz * half_res;
            c.dw[k][2] = wx * wy * (cz ? 1.f : -1.f) * half_res;
        }
    }
}

}  // namespace

std::vector<torch::Tensor> grid_forward(torch::Tensor table, torch::Tensor x, torch::Tensor meta, int64_t F, bool with_jac) {
    TORCH_CHECK(table.dtype() == torch::kFloat32 && x.dtype() == torch::kFloat32, "float32 expected");
    const int64_t P = x.size(0), L = meta.size(0), C = L * F;
    auto feat = torch::zeros({P, C}, x.options());
    auto jac = with_jac ? torch::zeros({P, 3, C}, x.options()) : torch::zeros({0}, x.options());
    const float* tp = table.data_ptr<float>();
    const float* xp = x.data_ptr<float>();
    const int64_t* mp = meta.data_ptr<int64_t>();
    float* fp = feat.data_ptr<float>();
    float* jp = with_jac ? jac.data_ptr<float>() : nullptr;
#pragma omp parallel for schedule(static)
    for (int64_t p = 0; p < P; ++p) {
        Cell c;
        for (int64_t l = 0; l < L; ++l) {
            cell_for(xp + 3 * p, mp[4 * l], mp[4 * l + 1], mp[4 * l + 2], mp[4 * l + 3] != 0, with_jac, c);
            for (int64_t ff = 0; ff < F; ++ff) {
                float acc = 0.f, a0 = 0.f, a1 = 0.f, a2 = 0.f;
                for (int k = 0; k < 8; ++k) {
                    const float v = tp[c.idx[k] * F + ff];
                    acc += c.w[k] * v;
                    if (with_jac) {
                        a0 += c.dw[k][0] * v;
                        a1 += c.dw[k][1] * v;
                        a2 += c.dw[k][2] * v;
                    }
                }
                const int64_t col = l * F + ff;
                fp[p * C + col] = acc;
                if (with_jac) {
                    jp[(p * 3 + 0) * C + col] = a0;
                    jp[(p * 3 + 1) * C + col] = a1;
                    jp[(p * 3 + 2) * C + col] = a2;
                }
            }
        }
    }
    return {feat, jac};
}

torch::Tensor grid_backward(torch::Tensor grad_feat, torch::Tensor grad_jac, torch::Tensor x, torch::Tensor meta, int64_t rows, int64_t F) {
    // Each thread scatters into its own copy of the table gradient (no atomics), then the copies are summed.
    const int64_t P = x.size(0), L = meta.size(0), C = L * F;
    const int nthreads = omp_get_max_threads();
    auto partial = torch::zeros({nthreads, rows, F}, x.options());
    const bool has_feat = grad_feat.numel() > 0;
    const bool has_jac = grad_jac.numel() > 0;
    const float* gf = has_feat ? grad_feat.data_ptr<float>() : nullptr;
    const float* gj = has_jac ? grad_jac.data_ptr<float>() : nullptr;
    const float* xp = x.data_ptr<float>();
    const int64_t* mp = meta.data_ptr<int64_t>();
    float* part = partial.data_ptr<float>();
#pragma omp parallel num_threads(nthreads)
    {
        float* gt = part + (int64_t)omp_get_thread_num() * rows * F;
        Cell c;
#pragma omp for schedule(static)
        for (int64_t p = 0; p < P; ++p) {
            for (int64_t l = 0; l < L; ++l) {
                cell_for(xp + 3 * p, mp[4 * l], mp[4 * l + 1], mp[4 * l + 2], mp[4 * l + 3] != 0, has_jac, c);
                for (int64_t ff = 0; ff < F; ++ff) {
                    const int64_t col = l * F + ff;
                    const float g = has_feat ? gf[p * C + col] : 0.f;
                    float g0 = 0.f, g1 = 0.f, g2 = 0.f;
                    if (has_jac) {
                        g0 = gj[(p * 3 + 0) * C + col];
                        g1 = gj[(p * 3 + 1) * C + col];
                        g2 = gj[(p * 3 + 2) * C + col];
                    }
                    for (int k = 0; k < 8; ++k) {
                        float v = c.w[k] * g;
                        if (has_jac) v += c.dw[k][0] * g0 + c.dw[k][1] * g1 + c.dw[k][2] * g2;
                        gt[c.idx[k] * F + ff] += v;
                    }
                }
            }
        }
    }
    return nthreads == 1 ? partial[0] : partial.sum(0);
}

// Softplus(beta) and its slope sigmoid(beta z) in one pass (the SDF MLP needs both), and the fused
// backward: grad_z = g_a * s + g_s * beta * s * (1 - s).
std::vector<torch::Tensor> softplus_slope_forward(torch::Tensor z, double beta) {
    auto zc = z.contiguous();
    auto a = torch::empty_like(zc);
    auto s = torch::empty_like(zc);
    const float* zp = zc.data_ptr<float>();
    float* ap = a.data_ptr<float>();
    float* sp = s.data_ptr<float>();
    const float b = (float)beta, inv_b = 1.f / (float)beta;
    const int64_t n = zc.numel();
#pragma omp parallel for simd schedule(static)
    for (int64_t i = 0; i < n; ++i) {  // branch-free so the loop vectorises (expf / logf from libmvec)
        const float z = zp[i];
        const float bz = b * z;
        const float e = expf(-fabsf(bz));  // in (0, 1]: no overflow for any z
        const float inv = 1.f / (1.f + e);
        sp[i] = bz >= 0.f ? inv : e * inv;
        ap[i] = fmaxf(z, 0.f) + logf(1.f + e) * inv_b;
    }
    return {a, s};
}

torch::Tensor softplus_slope_backward(torch::Tensor grad_a, torch::Tensor grad_s, torch::Tensor s, double beta) {
    auto ga = grad_a.contiguous();
    auto gs = grad_s.contiguous();
    auto out = torch::empty_like(s);
    const float* gap = ga.data_ptr<float>();
    const float* gsp = gs.numel() ? gs.data_ptr<float>() : nullptr;
    const float* sp = s.data_ptr<float>();
    float* op = out.data_ptr<float>();
    const float b = (float)beta;
    const int64_t n = s.numel();
#pragma omp parallel for schedule(static)
    for (int64_t i = 0; i < n; ++i) {
        float v = gap[i] * sp[i];
        if (gsp) v += gsp[i] * b * sp[i] * (1.f - sp[i]);
        op[i] = v;
    }
    return out;
}

PYBIND11_MODULE(TORCH_EXTENSION_NAME, m) {
    m.def("softplus_slope_forward", &softplus_slope_forward, "softplus(beta) and sigmoid(beta z)");
    m.def("softplus_slope_backward", &softplus_slope_backward, "fused backward of softplus_slope");
    m.def("forward", &grid_forward, "grid features + Jacobian");
    m.def("backward", &grid_backward, "grid table gradient");
}
