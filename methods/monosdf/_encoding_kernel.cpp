// Positional encoding of the SDF network's input (field.py::SDFNetwork.encode) and the chain rule of its
// explicit gradient, one pass per point each. Same contract as the PyTorch twin (tests compare them); the
// twin's elementwise ops over (P, F, 3) tensors broadcast against (1, F, 1) frequencies, which PyTorch runs
// as inner loops of 3 elements (~12 % of a training step, measured: docs/studies/monosdf-speed.md).
//
// Layout of pe (P, 3 + 6F): [u (3), sin(f_0 u) (3), ..., sin(f_{F-1} u) (3), cos(f_0 u) (3), ..., cos(f_{F-1} u) (3)].
#include <torch/extension.h>
#include <algorithm>
#include <cmath>
#include <math.h>
#include <vector>
#include <omp.h>

// u: (P, 3), freqs: (F,) -> pe (P, 3 + 6F).
// Blocks of kEncodeBlock points: each (frequency, axis) column is one loop over the block's points, with the
// sines and the cosines in two separate loops, which the compiler vectorises into glibc's vector sinf / cosf
// (libmvec, -ffast-math: 16 lanes with AVX-512); one loop computing both becomes a scalar sincosf per value
// (measured: ~10 % of a training step at 1 thread, perf). Where libmvec is absent the loops stay scalar.
constexpr int64_t kEncodeBlock = 64;

torch::Tensor pe_encode(torch::Tensor u, torch::Tensor freqs) {
    TORCH_CHECK(u.dtype() == torch::kFloat32 && u.dim() == 2 && u.size(1) == 3, "pe_encode: float32 (P, 3) points expected");
    auto uc = u.contiguous();
    auto fc = freqs.to(torch::kFloat32).contiguous();
    const int64_t P = uc.size(0), F = fc.numel(), D = 3 + 6 * F;
    auto pe = torch::empty({P, D}, uc.options());
    const float* up = uc.data_ptr<float>();
    const float* fp = fc.data_ptr<float>();
    float* op = pe.data_ptr<float>();
    const int64_t blocks = (P + kEncodeBlock - 1) / kEncodeBlock;
#pragma omp parallel for schedule(static)
    for (int64_t b = 0; b < blocks; ++b) {
        const int64_t p0 = b * kEncodeBlock, n = std::min(kEncodeBlock, P - p0);
        float arg[kEncodeBlock], sv[kEncodeBlock], cv[kEncodeBlock];
        for (int64_t i = 0; i < n; ++i) {
            float* row = op + D * (p0 + i);
            row[0] = up[3 * (p0 + i)];
            row[1] = up[3 * (p0 + i) + 1];
            row[2] = up[3 * (p0 + i) + 2];
        }
        for (int64_t k = 0; k < F; ++k) {
            for (int d = 0; d < 3; ++d) {
                for (int64_t i = 0; i < n; ++i) arg[i] = fp[k] * up[3 * (p0 + i) + d];
#pragma omp simd
                for (int64_t i = 0; i < n; ++i) sv[i] = sinf(arg[i]);
#pragma omp simd
                for (int64_t i = 0; i < n; ++i) cv[i] = cosf(arg[i]);
                float* s = op + D * p0 + 3 + 3 * k + d;
                float* c = s + 3 * F;
                for (int64_t i = 0; i < n; ++i) {
                    s[D * i] = sv[i];
                    c[D * i] = cv[i];
                }
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
