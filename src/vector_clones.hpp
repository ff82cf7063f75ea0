// Clones of a function for the vector widths of x86-64, one picked once at load time from what the CPU has (GCC's
// and Clang's target_clones): AVX-512, AVX2 and the baseline (SSE2). IEEE operations round the same at every width
// and fused multiply-adds are off (CMakeLists.txt), so every clone gives the same bits; tests run the AVX2 clones
// under valgrind (tests/CMakeLists.txt, lattice_model_test.avx2_clones). Elsewhere (aarch64, whose vectors are its
// baseline) a function is compiled once, as written.
#pragma once

#if defined(__x86_64__)
#define TISSUE_CLONES __attribute__((target_clones("avx512f", "avx2", "default")))
// x86-64-v4 (AVX-512 F, BW, CD, DQ, VL) and the baseline: for 64-bit lane multiplies (AVX-512 DQ's vpmullq)
#define TISSUE_CLONES_V4 __attribute__((target_clones("arch=x86-64-v4", "default")))
#else
#define TISSUE_CLONES
#define TISSUE_CLONES_V4
#endif
