// Float32 denormal mode (FTZ: flush results to zero, DAZ: read denormal operands as zero) in every thread that
// runs this process's tensor arithmetic. torch.set_flush_denormal sets it in the calling thread only, and the
// mode is per thread (x86 MXCSR), so the OpenMP pool that runs ATen's parallel ops and MKL's products keeps IEEE
// arithmetic: a 2-thread training step lost most of flush_denormals' gain (docs/studies/monosdf-speed.md).
// ATen, MKL (GNU threading) and this extension share one libgomp (torch/lib/libgomp.so.1), so one parallel
// region reaches every pool thread; threads the pool creates later inherit the creating thread's mode (POSIX).
#include <torch/extension.h>
#include <omp.h>
#include <cstdint>
#include <vector>
#if defined(__SSE__) || defined(__x86_64__)
#include <xmmintrin.h>
#define HAVE_MXCSR 1
#endif

namespace {
#ifdef HAVE_MXCSR
constexpr unsigned kFtzDaz = 0x8040u;  // MXCSR bit 15 (FTZ) | bit 6 (DAZ)

void set_this_thread(bool on) {
    const unsigned csr = _mm_getcsr();
    _mm_setcsr(on ? (csr | kFtzDaz) : (csr & ~kFtzDaz));
}

bool this_thread_flushes() { return (_mm_getcsr() & kFtzDaz) == kFtzDaz; }
#endif
}  // namespace

// Sets (on) or clears FTZ and DAZ in every thread of an OpenMP team of omp_get_max_threads() threads, the calling
// thread included (it is the team's thread 0); returns false where the CPU has no MXCSR (nothing changed).
bool set_flush_denormal_all_threads(bool on) {
#ifdef HAVE_MXCSR
#pragma omp parallel
    { set_this_thread(on); }
    return true;
#else
    (void)on;
    return false;
#endif
}

// Per OpenMP thread (index = omp_get_thread_num() in a team of omp_get_max_threads()): 1 if FTZ and DAZ are both
// set, 0 if not, -1 where the CPU has no MXCSR. For tests and diagnostics.
std::vector<int64_t> flush_denormal_per_thread() {
    std::vector<int64_t> mode(omp_get_max_threads(), -1);
#ifdef HAVE_MXCSR
#pragma omp parallel
    { mode[omp_get_thread_num()] = this_thread_flushes() ? 1 : 0; }
#endif
    return mode;
}
