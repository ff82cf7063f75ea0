//                 tissue: the divider's throughput on this CPU (a micro-benchmark)
//
// What it measures: nanoseconds an instruction of zmm square roots (vsqrtpd), divisions (vdivpd) and approximate
// reciprocal square roots (vrsqrt14pd), of ymm square roots, and of zmm multiply-adds, each in 8 independent
// chains, so that throughput and not latency sets the pace (for instructions whose latency is at most 8x their
// issue interval). The spring kernel's pull does one square root and one division a spring (docs/benchmarks.md,
// "A Zen 4 host"): their cost here against a row's time says how much of the explicit step is the divider's.
//
// How to run (from the repository root; needs AVX-512; about 5 s):
//   g++ -O2 -mavx512f -mfma -o /tmp/divider run_scripts/divider.cpp && /tmp/divider
// Sample output (AMD Zen 4, 2026-12-04): vsqrtpd zmm 4.364  vdivpd zmm 2.456  vrsqrt14pd zmm 0.652  vsqrtpd ymm
// 2.456  vfmadd zmm 0.625 (ns an instruction).
//
// Steps: 1. each instruction in 8 chains, 2 x 10^7 rounds, timed; 2. the times an instruction, printed.
#include <immintrin.h>

#include <chrono>
#include <cstdio>

int main() {
  constexpr int kRounds = 20000000, kChains = 8;
  using Clock = std::chrono::steady_clock;
  // 1. Each instruction in 8 chains (the empty asm keeps every result live and each round after the one before).
  __m512d a[kChains], b[kChains], c[kChains], e[kChains];
  __m256d d[kChains];
  for (int j = 0; j < kChains; ++j) {
    a[j] = _mm512_set1_pd(1.0 + j * 0.1), b[j] = _mm512_set1_pd(2.0 + j), c[j] = _mm512_set1_pd(1.0 + j);
    d[j] = _mm256_set1_pd(1.0 + j), e[j] = _mm512_set1_pd(1.0 + j);
  }
  const __m512d m = _mm512_set1_pd(1.0000001);
  // ns an instruction of op applied to each chain of v, round after round
  auto time = [&](auto* v, auto op) {
    const auto t0 = Clock::now();
    for (int i = 0; i < kRounds; ++i)
      for (int j = 0; j < kChains; ++j) {
        v[j] = op(v[j]);
        __asm__ volatile("" : "+v"(v[j]));
      }
    const double ns = std::chrono::duration<double, std::nano>(Clock::now() - t0).count();
    return ns / (static_cast<double>(kChains) * kRounds);
  };
  const double sqrt_zmm = time(a, [](__m512d x) { return _mm512_sqrt_pd(x); });
  const double div_zmm = time(b, [&](__m512d x) { return _mm512_div_pd(x, a[0]); });
  const double rsqrt_zmm = time(c, [](__m512d x) { return _mm512_rsqrt14_pd(x); });
  const double sqrt_ymm = time(d, [](__m256d x) { return _mm256_sqrt_pd(x); });
  const double fma_zmm = time(e, [&](__m512d x) { return _mm512_fmadd_pd(x, m, m); });
  // 2. The times an instruction (and a checksum, so that nothing is optimized away).
  double sum = 0;
  for (int j = 0; j < kChains; ++j) sum += a[j][0] + b[j][0] + c[j][0] + d[j][0] + e[j][0];
  std::printf("vsqrtpd zmm %.3f  vdivpd zmm %.3f  vrsqrt14pd zmm %.3f  vsqrtpd ymm %.3f  vfmadd zmm %.3f "
              "(ns an instruction; checksum %g)\n",
              sqrt_zmm, div_zmm, rsqrt_zmm, sqrt_ymm, fma_zmm, sum);
}
