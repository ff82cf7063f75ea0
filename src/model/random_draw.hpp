// The random numbers of the random topologies: 53-bit uniform draws of std::mt19937_64, whose sequence the C++
// standard fixes, so a seed gives the same cloud with any standard library and on any rank count.
#pragma once
#include <random>

namespace tissue {

// Uniform in [0, 1).
inline double uniform(std::mt19937_64& rng) { return static_cast<double>(rng() >> 11) * 0x1.0p-53; }

}  // namespace tissue
