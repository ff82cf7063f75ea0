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
  const auto t0 = Clock::now();
  for (int i = 0; i < kRounds; ++i)
    for (int j = 0; j < kChains; ++j) {
      a[j] = _mm512_sqrt_pd(a[j]);
      __asm__ volatile("" : "+v"(a[j]));
    }
  const auto t1 = Clock::now();
  for (int i = 0; i < kRounds; ++i)
    for (int j = 0; j < kChains; ++j) {
      b[j] = _mm512_div_pd(b[j], a[j]);
      __asm__ volatile("" : "+v"(b[j]));
    }
  const auto t2 = Clock::now();
  for (int i = 0; i < kRounds; ++i)
    for (int j = 0; j < kChains; ++j) {
      c[j] = _mm512_rsqrt14_pd(c[j]);
      __asm__ volatile("" : "+v"(c[j]));
    }
  const auto t3 = Clock::now();
  for (int i = 0; i < kRounds; ++i)
    for (int j = 0; j < kChains; ++j) {
      d[j] = _mm256_sqrt_pd(d[j]);
      __asm__ volatile("" : "+v"(d[j]));
    }
  const auto t4 = Clock::now();
  for (int i = 0; i < kRounds; ++i)
    for (int j = 0; j < kChains; ++j) {
      e[j] = _mm512_fmadd_pd(e[j], m, m);
      __asm__ volatile("" : "+v"(e[j]));
    }
  const auto t5 = Clock::now();
  // 2. The times an instruction (and a checksum, so that nothing is optimized away).
  double sum = 0;
  for (int j = 0; j < kChains; ++j) sum += a[j][0] + b[j][0] + c[j][0] + d[j][0] + e[j][0];
  auto ns = [&](Clock::time_point x, Clock::time_point y) {
    return std::chrono::duration<double, std::nano>(y - x).count() / (static_cast<double>(kChains) * kRounds);
  };
  std::printf("vsqrtpd zmm %.3f  vdivpd zmm %.3f  vrsqrt14pd zmm %.3f  vsqrtpd ymm %.3f  vfmadd zmm %.3f "
              "(ns an instruction; checksum %g)\n",
              ns(t0, t1), ns(t1, t2), ns(t2, t3), ns(t3, t4), ns(t4, t5), sum);
}
