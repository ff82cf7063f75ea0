#include "src/physics/rest_pull.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <map>
#include <unordered_map>

#include "src/vector_clones.hpp"

namespace tissue {

namespace {

// The kernels below (TISSUE_CLONES) come in AVX-512, AVX2 and baseline clones, picked at run time, with the same
// bits, as the force kernels' (src/vector_clones.hpp).

constexpr int kMaxDirections = 16;     // the masks' bits: forward s, backward 16 + s
constexpr int kMaxPattern = 13;        // 16 + s below make()'s flag bits (29, 30, 31)
constexpr int kChunk = 1024;           // rows handed to final_rows at a time (in cache still)
constexpr double kTolerance = 1e-12;   // as SpringKernel::rest_stencil: a rest separation is its direction's

// The distinct a = sqrt(k) n of the springs at rest: keyed by the connection type and the rest separation rounded
// (2^-20 of l0), each key's entries told apart by their rest separation (to kTolerance of l0), not by the local
// offset (a ghost's varies from row to row). A lattice has a few dozen.
class Table {
public:
  explicit Table(std::size_t cap) : cap_(cap) {}
  // The entry of a spring (type, rest separation d), made on first sight; -1 past the cap. guess: an entry to try
  // first (the last one of the spring's type and offset hits almost always).
  int find(int type, const double* d, double k, double l0, int guess) {
    if (guess >= 0 && matches(entries_[guess], type, d, l0)) return guess;
    std::uint64_t key = static_cast<std::uint64_t>(type);
    for (int r = 0; r < 3; ++r)
      key = key * 0x9E3779B97F4A7C15ull + static_cast<std::uint64_t>(std::llround(d[r] / l0 * 1048576.0));
    auto [it, fresh] = head_.try_emplace(key, -1);
    int* link = &it->second;
    for (int e = *link; e >= 0; link = &entries_[e].next, e = *link)
      if (matches(entries_[e], type, d, l0)) return e;
    if (entries_.size() >= cap_) return -1;
    const double len = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    if (!(len > 0)) return -1;
    const double s = std::sqrt(k) / len;
    entries_.push_back({type, {d[0], d[1], d[2]}, -1});
    for (int r = 0; r < 3; ++r) a_.push_back(s * d[r]);
    *link = static_cast<int>(entries_.size()) - 1;
    return *link;
  }
  std::vector<double>& a() { return a_; }

private:
  struct Entry {
    int type;
    double d[3];
    int next;
  };
  static bool matches(const Entry& e, int type, const double* d, double l0) {
    if (e.type != type) return false;
    const double scale = kTolerance * l0;
    return std::abs(d[0] - e.d[0]) <= scale && std::abs(d[1] - e.d[1]) <= scale && std::abs(d[2] - e.d[2]) <= scale;
  }
  std::size_t cap_;
  std::vector<Entry> entries_;
  std::vector<double> a_;
  std::unordered_map<std::uint64_t, int> head_;
};

// Full rows [begin, end): every direction's spring both ways, a_s and o_s constants of the pattern (D of them; D = 0:
// `directions` at run time). The two springs of a direction share a_s, so (a_s . (w_forward + w_backward)) a_s.
template <int D>
__attribute__((always_inline)) inline void full_body(int begin, int end, int directions, const int* offset_,
                                                     const double* a_, const double* __restrict u,
                                                     double* __restrict out) {
  constexpr int kSlots = D > 0 ? D : kMaxDirections;
  const int n = D > 0 ? D : directions;
  long off[kSlots];
  double a0[kSlots], a1[kSlots], a2[kSlots];
  for (int s = 0; s < n; ++s) off[s] = 3L * offset_[s], a0[s] = a_[3 * s], a1[s] = a_[3 * s + 1], a2[s] = a_[3 * s + 2];
  for (long i = begin; i < end; ++i) {
    const double* ui = u + 3 * i;
    const double v0 = ui[0], v1 = ui[1], v2 = ui[2];
    double o0 = 0.0, o1 = 0.0, o2 = 0.0;
#pragma GCC unroll 16
    for (int s = 0; s < n; ++s) {
      const double *p = ui + off[s], *q = ui - off[s];
      const double w0 = (v0 - p[0]) + (v0 - q[0]), w1 = (v1 - p[1]) + (v1 - q[1]), w2 = (v2 - p[2]) + (v2 - q[2]);
      const double t = a0[s] * w0 + a1[s] * w1 + a2[s] * w2;
      o0 += t * a0[s], o1 += t * a1[s], o2 += t * a2[s];
    }
    double* oi = out + 3 * i;
    oi[0] = o0, oi[1] = o1, oi[2] = o2;
  }
}

// Masked rows: the same sum over the springs present (mask bit s forward, bit 16 + s backward); a missing one is
// read at the row itself, whose difference is exactly +0.0 (nothing read out of the local rows).
template <int D>
__attribute__((always_inline)) inline void masked_body(int begin, int end, int directions, const int* offset_,
                                                       const double* a_, const std::uint32_t* __restrict mask,
                                                       const double* __restrict u, double* __restrict out) {
  constexpr int kSlots = D > 0 ? D : kMaxDirections;
  const int n = D > 0 ? D : directions;
  long off[kSlots];
  double a0[kSlots], a1[kSlots], a2[kSlots];
  for (int s = 0; s < n; ++s) off[s] = 3L * offset_[s], a0[s] = a_[3 * s], a1[s] = a_[3 * s + 1], a2[s] = a_[3 * s + 2];
  for (long i = begin; i < end; ++i) {
    const std::uint32_t m = mask[i - begin];
    const double* ui = u + 3 * i;
    const double v0 = ui[0], v1 = ui[1], v2 = ui[2];
    double o0 = 0.0, o1 = 0.0, o2 = 0.0;
#pragma GCC unroll 16
    for (int s = 0; s < n; ++s) {
      const double* p = ui + ((m >> s & 1u) ? off[s] : 0L);
      const double* q = ui - ((m >> (16 + s) & 1u) ? off[s] : 0L);
      const double w0 = (v0 - p[0]) + (v0 - q[0]), w1 = (v1 - p[1]) + (v1 - q[1]), w2 = (v2 - p[2]) + (v2 - q[2]);
      const double t = a0[s] * w0 + a1[s] * w1 + a2[s] * w2;
      o0 += t * a0[s], o1 += t * a1[s], o2 += t * a2[s];
    }
    double* oi = out + 3 * i;
    oi[0] = o0, oi[1] = o1, oi[2] = o2;
  }
}

TISSUE_CLONES void full3(int b, int e, int d, const int* o, const double* a, const double* u, double* out) {
  full_body<3>(b, e, d, o, a, u, out);
}
TISSUE_CLONES void full9(int b, int e, int d, const int* o, const double* a, const double* u, double* out) {
  full_body<9>(b, e, d, o, a, u, out);
}
TISSUE_CLONES void full13(int b, int e, int d, const int* o, const double* a, const double* u, double* out) {
  full_body<13>(b, e, d, o, a, u, out);
}
TISSUE_CLONES void full_any(int b, int e, int d, const int* o, const double* a, const double* u, double* out) {
  full_body<0>(b, e, d, o, a, u, out);
}
TISSUE_CLONES void masked9(int b, int e, int d, const int* o, const double* a, const std::uint32_t* m,
                                const double* u, double* out) {
  masked_body<9>(b, e, d, o, a, m, u, out);
}
TISSUE_CLONES void masked_any(int b, int e, int d, const int* o, const double* a, const std::uint32_t* m,
                                   const double* u, double* out) {
  masked_body<0>(b, e, d, o, a, m, u, out);
}

// Listed rows [begin, end): each its springs in connection order.
void listed_rows(int begin, int end, const int* start, const int* other, const std::uint32_t* which, const double* a,
                 const double* __restrict u, double* __restrict out) {
  for (int i = begin; i < end; ++i) {
    const double* ui = u + 3 * static_cast<long>(i);
    double o0 = 0.0, o1 = 0.0, o2 = 0.0;
    for (int e = start[i - begin]; e < start[i - begin + 1]; ++e) {
      const double* uj = u + 3 * static_cast<long>(other[e]);
      const double* k = a + 3 * static_cast<std::size_t>(which[e]);
      const double t = k[0] * (ui[0] - uj[0]) + k[1] * (ui[1] - uj[1]) + k[2] * (ui[2] - uj[2]);
      o0 += t * k[0], o1 += t * k[1], o2 += t * k[2];
    }
    double* oi = out + 3 * static_cast<long>(i);
    oi[0] = o0, oi[1] = o1, oi[2] = o2;
  }
}

// Each connection's table entry while the rows are built: 1 B a connection (a lattice has a few dozen entries),
// the rare others in a map.
class Entries {
public:
  explicit Entries(int n) : small_(n) {}
  void set(int c, int e) {
    small_[c] = static_cast<std::uint8_t>(std::min(e, 255));
    if (e >= 255) large_[c] = e;
  }
  int operator()(int c) const { return small_[c] < 255 ? small_[c] : large_.at(c); }

private:
  std::vector<std::uint8_t> small_;
  std::unordered_map<int, int> large_;
};

// f(c, a, b) for every connection in order, the ends decoded a window at a time (ConnectionEnd::decode: no run
// search a value, whatever the two ends' storage).
template <class F>
void each_connection(const LocalModel& model, F&& f) {
  constexpr int kWindow = 4096;
  const int nc = model.connections();
  int a[kWindow], b[kWindow];
  for (int c0 = 0; c0 < nc; c0 += kWindow) {
    const int c1 = std::min(nc, c0 + kWindow);
    model.end_a.decode(c0, c1, a), model.end_b.decode(c0, c1, b);
    for (int c = c0; c < c1; ++c) f(c, a[c - c0], b[c - c0]);
  }
}

}  // namespace

std::unique_ptr<RestPull> RestPull::make(const LocalModel& model) {
  if (!model.typed()) return nullptr;  // k may change (calibration): the push form
  const int owned = model.owned, nc = model.connections();
  if (owned == 0) return nullptr;
  const ConnectionColumn kc = model.table.stiffness_column(), lc = model.table.rest_length_column();
  const double* X = model.rest.data();
  // 1. Each spring's a (an entry of the table, kept until the rows are built), and the rows'
  //    most frequent forward pattern ((offset, entry) by increasing offset): the interior's.
  Table table(std::min<std::size_t>(65535, std::max<std::size_t>(1024, owned / 64)));
  Entries entry(nc);
  bool fits = true;
  struct Candidate {
    std::vector<std::pair<int, int>> pattern;
    long rows = 0;
  };
  std::vector<Candidate> candidates;
  constexpr std::size_t kCandidates = 64;
  std::vector<std::pair<int, int>> run, last_run;
  int last_candidate = -1;
  // The entry last found for a (type, offset), direct-mapped: a lattice's springs of one direction hit it.
  constexpr unsigned kSlots = 4096;
  std::vector<int> guess(kSlots, -1);
  auto close_run = [&]() {
    if (run.empty()) return;
    if (last_candidate >= 0 && run == last_run) {
      ++candidates[last_candidate].rows;
    } else {
      last_candidate = -1;
      for (std::size_t q = 0; q < candidates.size() && last_candidate < 0; ++q)
        if (candidates[q].pattern == run) last_candidate = static_cast<int>(q);
      if (last_candidate < 0 && candidates.size() < kCandidates) {
        candidates.push_back({run, 0});
        last_candidate = static_cast<int>(candidates.size()) - 1;
      }
      if (last_candidate >= 0) ++candidates[last_candidate].rows;
      last_run = run;
    }
    run.clear();
  };
  int row = -1;
  each_connection(model, [&](int c, int a, int b) {
    if (!fits) return;
    if (a != row) close_run(), row = a;
    const int t = kc.type[c];
    double d[3];
    for (int r = 0; r < 3; ++r) d[r] = X[3 * static_cast<std::size_t>(b) + r] - X[3 * static_cast<std::size_t>(a) + r];
    int& slot = guess[(static_cast<unsigned>(b - a) * 31u + static_cast<unsigned>(t)) & (kSlots - 1)];
    const int e = table.find(t, d, kc.value[t], lc.value[lc.type ? lc.type[c] : c], slot);
    if (e < 0) {
      fits = false;
      return;
    }
    entry.set(c, e);
    slot = e;
    run.push_back({b - a, e});
  });
  close_run();
  if (!fits || candidates.empty()) return nullptr;
  const Candidate* best = nullptr;
  for (const Candidate& cand : candidates) {
    const auto& p = cand.pattern;
    // Offsets positive and strictly increasing (a row's connections need not be in that order: direction_of below
    // is sized by the last offset), and at most 13 directions (backward bit 16 + s below the flags' bits 29-31).
    if (static_cast<int>(p.size()) > kMaxPattern || p.front().first <= 0) continue;
    bool increasing = true;
    for (std::size_t s = 1; s < p.size(); ++s) increasing = increasing && p[s].first > p[s - 1].first;
    if (!increasing) continue;
    if (!best || cand.rows > best->rows) best = &cand;
  }
  if (!best) return nullptr;
  std::unique_ptr<RestPull> pull(new RestPull);
  RestPull& P = *pull;
  P.owned_ = owned;
  P.directions_ = static_cast<int>(best->pattern.size());
  const int D = P.directions_;
  for (const auto& [o, e] : best->pattern) {
    P.offset_.push_back(o);
    for (int r = 0; r < 3; ++r) P.pattern_a_.push_back(table.a()[3 * static_cast<std::size_t>(e) + r]);
  }
  // 2. Each owned row's springs against the pattern's offsets: forward bit s, backward bit 16 + s; kVariant where
  //    one has another a than the pattern's (a face's type), kOther for any other spring (listed).
  constexpr std::uint32_t kOther = 1u << 31, kVariant = 1u << 30, kFlags = kOther | kVariant;
  std::vector<std::uint32_t> bits(owned, 0u);
  std::vector<std::int8_t> direction_of(best->pattern.back().first + 1, -1);  // by offset
  for (int s = 0; s < D; ++s) direction_of[best->pattern[s].first] = static_cast<std::int8_t>(s);
  auto direction = [&](int o) {
    return o > 0 && o < static_cast<int>(direction_of.size()) ? static_cast<int>(direction_of[o]) : -1;
  };
  each_connection(model, [&](int c, int a, int b) {
    const int s = direction(b - a);
    const std::uint32_t variant = s >= 0 && best->pattern[s].second != entry(c) ? kVariant : 0u;
    auto mark = [&](int r, std::uint32_t bit) {
      if (r >= owned) return;
      bits[r] |= (s < 0 || (bits[r] & bit)) ? kOther : bit | variant;  // twice the same spring: listed
    };
    mark(a, s < 0 ? 0u : 1u << s);
    mark(b, s < 0 ? 0u : 1u << (16 + s));
  });
  const std::uint32_t full = ((1u << D) - 1u) | (((1u << D) - 1u) << 16);
  // 3. The rows with a part of the pattern or other a's (faces, edges, row ends): each direction's a, the same both
  //    ways (else listed), as a variant of the pattern; kept as an ordinal into `tuples` meanwhile.
  //    Their masks move to `partial_masks`, bits keeps their ordinal (kPartial).
  constexpr std::uint32_t kPartial = 1u << 29, kOrdinal = kPartial - 1u;
  std::vector<std::uint16_t> tuples;  // D a row: its directions' entries (kNone: absent both ways)
  constexpr std::uint16_t kNone = 0xFFFF;
  std::vector<std::uint32_t> partial_masks;
  for (int r = 0; r < owned; ++r)
    if (!(bits[r] & kOther) && (bits[r] & ~kFlags) != full) {
      partial_masks.push_back(bits[r] & ~kFlags);
      bits[r] = kPartial | static_cast<std::uint32_t>(partial_masks.size() - 1);
    }
  tuples.assign(partial_masks.size() * D, kNone);
  auto partial_of = [&](int r) {
    return r < owned && (bits[r] & (kPartial | kOther)) == kPartial ? static_cast<int>(bits[r] & kOrdinal) : -1;
  };
  each_connection(model, [&](int c, int a, int b) {
    const int s = direction(b - a);
    if (s < 0) return;
    for (const int r : {a, b}) {
      const int q = partial_of(r);
      if (q < 0) continue;
      std::uint16_t& t = tuples[static_cast<std::size_t>(q) * D + s];
      if (t != kNone && t != entry(c)) bits[r] |= kOther;  // two a's in one direction: listed
      t = entry(c);
    }
  });
  // A full row whose a's are not all the pattern's is a variant too: found in the same way, from the listed springs'
  // pass below; here (rare: a lattice's full rows are the interior's) it is simply listed.
  for (int r = 0; r < owned; ++r)
    if ((bits[r] & kVariant) && (bits[r] & ~kFlags) == full) bits[r] |= kOther;
  auto kind_of = [&](std::uint32_t v) { return v & kOther ? kListed : v & kPartial ? kMasked : kFull; };
  for (int r = 0; r < owned; ++r) ++P.counts_[kind_of(bits[r])];
  if (2 * (P.counts_[kFull] + P.counts_[kMasked]) < owned) return nullptr;
  // 4. The runs (a masked run has one variant); the masked rows' masks; the listed rows' ordinals (in bits, kOther
  //    kept) and their springs.
  P.variants_ = P.pattern_a_;  // variant 0: the pattern
  std::map<std::vector<std::uint16_t>, int> variant_of;
  std::vector<std::uint16_t> tuple(D), last_tuple;
  int last_variant = -1;
  int listed = 0;
  for (int r = 0; r < owned; ++r) {
    const Kind k = kind_of(bits[r]);
    int variant = 0;
    if (k == kMasked) {
      const int q = partial_of(r);
      tuple.assign(tuples.begin() + static_cast<std::size_t>(q) * D, tuples.begin() + static_cast<std::size_t>(q + 1) * D);
      if (tuple == last_tuple) {
        variant = last_variant;
      } else {
        auto [it, fresh] = variant_of.try_emplace(tuple, static_cast<int>(P.variants_.size() / (3 * D)));
        if (fresh)
          for (int s = 0; s < D; ++s)
            for (int c = 0; c < 3; ++c)
              P.variants_.push_back(tuple[s] == kNone ? 0.0 : table.a()[3 * static_cast<std::size_t>(tuple[s]) + c]);
        variant = it->second;
        last_tuple = tuple, last_variant = variant;
      }
    }
    if (P.runs_.empty() || P.runs_.back().kind != k || P.runs_.back().variant != variant)
      P.runs_.push_back({r, k, k == kMasked ? static_cast<int>(P.masks_.size()) : listed, variant});
    if (k == kMasked) P.masks_.push_back(partial_masks[bits[r] & kOrdinal]);
    if (k == kListed) bits[r] = kOther | static_cast<std::uint32_t>(listed++);
  }
  P.runs_.push_back({owned, kFull, 0, 0});
  P.start_.assign(listed + 1, 0);
  if (listed == 0) {
    P.table_.clear();
    P.masks_.shrink_to_fit(), P.runs_.shrink_to_fit(), P.variants_.shrink_to_fit();
    return pull;
  }
  auto listed_row = [&](int r) { return r < owned && (bits[r] & kOther) ? static_cast<int>(bits[r] & ~kOther) : -1; };
  each_connection(model, [&](int, int a, int b) {
    if (const int q = listed_row(a); q >= 0) ++P.start_[q + 1];
    if (const int q = listed_row(b); q >= 0) ++P.start_[q + 1];
  });
  for (int q = 0; q < listed; ++q) P.start_[q + 1] += P.start_[q];
  P.other_.resize(P.start_[listed]);
  P.which_.resize(P.start_[listed]);
  std::vector<int> fill(P.start_.begin(), P.start_.end() - 1);
  each_connection(model, [&](int c, int a, int b) {
    if (const int q = listed_row(a); q >= 0) P.other_[fill[q]] = b, P.which_[fill[q]++] = entry(c);
    if (const int q = listed_row(b); q >= 0) P.other_[fill[q]] = a, P.which_[fill[q]++] = entry(c);
  });
  P.table_ = std::move(table.a());
  P.table_.shrink_to_fit(), P.masks_.shrink_to_fit(), P.runs_.shrink_to_fit(), P.variants_.shrink_to_fit();
  return pull;
}

void RestPull::apply(const double* u, double* out, FinalRows final_rows, void* context) const {
  const int D = directions_;
  const int* o = offset_.data();
  const double* a = pattern_a_.data();
  int handed = 0;
  for (std::size_t q = 0; q + 1 < runs_.size(); ++q) {
    const Run& r = runs_[q];
    const int end = runs_[q + 1].begin;
    for (int b = r.begin; b < end;) {
      const int e = std::min(end, b + kChunk);
      switch (r.kind) {
        case kFull:
          if (D == 9) full9(b, e, D, o, a, u, out);
          else if (D == 13) full13(b, e, D, o, a, u, out);
          else if (D == 3) full3(b, e, D, o, a, u, out);
          else full_any(b, e, D, o, a, u, out);
          break;
        case kMasked: {
          const std::uint32_t* m = masks_.data() + r.at + (b - r.begin);
          const double* v = variants_.data() + 3 * static_cast<std::size_t>(D) * r.variant;
          if (D == 9) masked9(b, e, D, o, v, m, u, out);
          else masked_any(b, e, D, o, v, m, u, out);
          break;
        }
        case kListed:
          listed_rows(b, e, start_.data() + r.at + (b - r.begin), other_.data(), which_.data(), table_.data(), u, out);
          break;
      }
      b = e;
      if (final_rows && b - handed >= kChunk) final_rows(context, handed, b), handed = b;
    }
  }
  if (final_rows && handed < owned_) final_rows(context, handed, owned_);
}

}  // namespace tissue
