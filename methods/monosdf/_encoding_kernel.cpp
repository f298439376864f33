// Positional encoding of the SDF network's input (field.py::SDFNetwork.encode) and the chain rule of its
// explicit gradient, one pass per point each. Same contract as the PyTorch twin (tests compare them); the
// twin's elementwise ops over (P, F, 3) tensors broadcast against (1, F, 1) frequencies, which PyTorch runs
// as inner loops of 3 elements (~12 % of a training step, measured: docs/monosdf.md, speed).
//
// Layout of pe (P, 3 + 6F): [u (3), sin(f_0 u) (3), ..., sin(f_{F-1} u) (3), cos(f_0 u) (3), ..., cos(f_{F-1} u) (3)].
#include <torch/extension.h>
#include <cmath>
#include <vector>
#include <omp.h>

// u: (P, 3), freqs: (F,) -> pe (P, 3 + 6F).
torch::Tensor pe_encode(torch::Tensor u, torch::Tensor freqs) {
    TORCH_CHECK(u.dtype() == torch::kFloat32 && u.dim() == 2 && u.size(1) == 3, "pe_encode: float32 (P, 3) points expected");
    auto uc = u.contiguous();
    auto fc = freqs.to(torch::kFloat32).contiguous();
    const int64_t P = uc.size(0), F = fc.numel(), D = 3 + 6 * F;
    auto pe = torch::empty({P, D}, uc.options());
    const float* up = uc.data_ptr<float>();
    const float* fp = fc.data_ptr<float>();
    float* op = pe.data_ptr<float>();
#pragma omp parallel for schedule(static)
    for (int64_t p = 0; p < P; ++p) {
        const float* x = up + 3 * p;
        float* row = op + D * p;
        row[0] = x[0];
        row[1] = x[1];
        row[2] = x[2];
        float* s = row + 3;
        float* c = row + 3 + 3 * F;
#pragma omp simd collapse(2)
        for (int64_t k = 0; k < F; ++k) {
            for (int d = 0; d < 3; ++d) {
                const float v = fp[k] * x[d];
                s[3 * k + d] = sinf(v);
                c[3 * k + d] = cosf(v);
            }
        }
    }
    return pe;
}

// d sdf / d u through the encoding: out[p, d] = gin[p, d] + sum_k f_k (gin_sin[p, k, d] cos[p, k, d] -
// gin_cos[p, k, d] sin[p, k, d]), with sin / cos read from pe. gin, pe: (P, 3 + 6F) -> (P, 3).
torch::Tensor pe_chain_forward(torch::Tensor gin, torch::Tensor pe, torch::Tensor freqs) {
    auto g = gin.contiguous();
    auto e = pe.contiguous();
    auto fc = freqs.to(torch::kFloat32).contiguous();
    const int64_t P = e.size(0), F = fc.numel(), D = 3 + 6 * F;
    TORCH_CHECK(g.dtype() == torch::kFloat32 && g.size(0) == P && g.size(1) == D && e.size(1) == D, "pe_chain: (P, 3 + 6F) inputs expected");
    auto out = torch::empty({P, 3}, e.options());
    const float* gp = g.data_ptr<float>();
    const float* ep = e.data_ptr<float>();
    const float* fp = fc.data_ptr<float>();
    float* op = out.data_ptr<float>();
#pragma omp parallel for schedule(static)
    for (int64_t p = 0; p < P; ++p) {
        const float* gr = gp + D * p;
        const float* er = ep + D * p;
        float acc[3] = {gr[0], gr[1], gr[2]};
        for (int64_t k = 0; k < F; ++k) {
            const float f = fp[k];
            for (int d = 0; d < 3; ++d) {
                const int64_t is = 3 + 3 * k + d, ic = 3 + 3 * F + 3 * k + d;
                acc[d] += f * (gr[is] * er[ic] - gr[ic] * er[is]);
            }
        }
        op[3 * p] = acc[0];
        op[3 * p + 1] = acc[1];
        op[3 * p + 2] = acc[2];
    }
    return out;
}

// Backward of pe_chain_forward with respect to gin (pe depends on the points only, which need no
// gradient): dgin[:, d] = dout[:, d], dgin_sin[k, d] = f_k cos dout[d], dgin_cos[k, d] = -f_k sin dout[d].
torch::Tensor pe_chain_backward(torch::Tensor dout, torch::Tensor pe, torch::Tensor freqs) {
    auto go = dout.contiguous();
    auto e = pe.contiguous();
    auto fc = freqs.to(torch::kFloat32).contiguous();
    const int64_t P = e.size(0), F = fc.numel(), D = 3 + 6 * F;
    auto dg = torch::empty({P, D}, e.options());
    const float* gop = go.data_ptr<float>();
    const float* ep = e.data_ptr<float>();
    const float* fp = fc.data_ptr<float>();
    float* dp = dg.data_ptr<float>();
#pragma omp parallel for schedule(static)
    for (int64_t p = 0; p < P; ++p) {
        const float* o = gop + 3 * p;
        const float* er = ep + D * p;
        float* row = dp + D * p;
        row[0] = o[0];
        row[1] = o[1];
        row[2] = o[2];
        for (int64_t k = 0; k < F; ++k) {
            const float f = fp[k];
            for (int d = 0; d < 3; ++d) {
                const int64_t is = 3 + 3 * k + d, ic = 3 + 3 * F + 3 * k + d;
                row[is] = f * er[ic] * o[d];
                row[ic] = -f * er[is] * o[d];
            }
        }
    }
    return dg;
}
