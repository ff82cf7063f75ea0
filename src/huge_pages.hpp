//                  tissue: when the program re-executes itself with glibc's huge pages for malloc
//
// The decision of src/huge_pages.cpp (which says why), apart from the re-execution so that a test can ask it.
// It runs before libc's own initializer: no environ, no stdio, no malloc; the arguments and plain string calls.
#pragma once

#include <cstddef>
#include <cstring>
#include <initializer_list>

namespace tissue {

// `tissue run` re-executes only for scenes of at least this many molecules (scanned_molecules, before any library
// initializer):
// the second start costs each rank 60-110 ms of CPU (the loader's relocations of ~107 libraries), and at 64,000
// molecules on 2 ranks the huge pages already cut the set-up by about 0.1 s a rank; below about 32^3 the whole
// set-up is shorter than the second start (docs/benchmarks.md, branch part18).
constexpr long long kHugePagesFromMolecules = 32768;

// The molecule count of a `tissue run` as far as a plain scan of its command line and scene text can tell (no
// TOML parser, no malloc: it runs before libc is initialized): the scene's `molecules = [a, b, c]` lines summed
// over bodies, the first body's replaced by the last `--set body.molecules=[a,b,c]`; -1 when unsure (no such line,
// several bodies with that --set, a line mentioning a mesh, a random cloud or interior molecules). The program
// re-executes when unsure: the default.
inline long long scanned_molecules(int argc, char* const* argv, const char* text) {
  auto product = [](const char* p) -> long long {  // "[a, b, c]" at p (blanks allowed); -1 otherwise
    while (*p == ' ' || *p == '\t') ++p;
    if (*p++ != '[') return -1;
    long long result = 1;
    for (int d = 0; d < 3; ++d) {
      while (*p == ' ' || *p == '\t') ++p;
      if (*p < '0' || *p > '9') return -1;
      long long v = 0;
      while (*p >= '0' && *p <= '9' && v < 100000000) v = 10 * v + (*p++ - '0');
      while (*p == ' ' || *p == '\t') ++p;
      if (*p++ != (d < 2 ? ',' : ']')) return -1;
      result *= v;
    }
    return result;
  };
  long long override_count = -1;
  for (int i = 2; i < argc && argv[i] != nullptr; ++i) {
    const char* a = argv[i];
    if (std::strcmp(a, "--") == 0) break;
    const char* value = nullptr;
    if (std::strcmp(a, "--set") == 0 && i + 1 < argc) value = argv[++i];
    else if (std::strncmp(a, "--set=", 6) == 0) value = a + 6;
    if (value != nullptr && std::strncmp(value, "body.molecules=", 15) == 0) override_count = product(value + 15);
    if (value != nullptr && std::strncmp(value, "body.molecules=", 15) == 0 && override_count < 0) return -1;
  }
  if (text == nullptr) return -1;
  long long total = 0;
  int lines = 0;
  for (const char* line = text; *line != '\0';) {
    const char* end = line;
    while (*end != '\0' && *end != '\n') ++end;
    const char* p = line;
    while (p < end && (*p == ' ' || *p == '\t')) ++p;
    if (p < end && *p != '#') {
      for (const char* q = p; q < end; ++q)
        for (const char* word : {"mesh", "random", "interior_molecules"})
          if (std::strncmp(q, word, std::strlen(word)) == 0) return -1;
      if (std::strncmp(p, "molecules", 9) == 0) {
        p += 9;
        while (*p == ' ' || *p == '\t') ++p;
        if (*p++ != '=') return -1;
        const long long n = product(p);
        if (n < 0) return -1;
        ++lines;
        total += n;
      }
    }
    line = *end == '\0' ? end : end + 1;
  }
  if (override_count >= 0) {
    if (lines > 1) return -1;
    return override_count;
  }
  return lines == 0 ? -1 : total;
}

// Re-executes the program with the huge-page tunable, unless huge_pages_entry() or the kernel says no; returns
// only when it does not.
void reexecute_with_huge_pages(int argc, char** argv, char** envp);

inline bool huge_pages_opted_out(const char* value) {
  for (const char* off : {"off", "0", "no", "false"})
    if (std::strcmp(value, off) == 0) return true;
  return false;
}

// The environment entry "GLIBC_TUNABLES=<the old tunables>:glibc.malloc.hugetlb=1" written into entry (size
// bytes), or false when this start stays as it is: not a computing command (run, restart, fit); the opt-out
// TISSUE_HUGE_PAGES=off|0|no|false; GLIBC_TUNABLES already naming glibc.malloc.hugetlb (the user's choice, or the
// re-executed image); valgrind (its preload in LD_PRELOAD, or under_valgrind); the kernel not granting huge pages
// on request; or an entry longer than size.
inline bool huge_pages_entry(int argc, char* const* argv, char* const* envp, bool granted_on_request,
                             bool under_valgrind, char* entry, std::size_t size) {
  auto starts_with = [](const char* s, const char* prefix) { return std::strncmp(s, prefix, std::strlen(prefix)) == 0; };
  if (argc < 2 || argv == nullptr || argv[1] == nullptr || envp == nullptr) return false;
  const char* command = argv[1];
  if (std::strcmp(command, "run") != 0 && std::strcmp(command, "restart") != 0 && std::strcmp(command, "fit") != 0)
    return false;
  const char* tunables = nullptr;
  for (std::size_t i = 0; envp[i] != nullptr; ++i) {
    const char* e = envp[i];
    if (starts_with(e, "TISSUE_HUGE_PAGES=") && huge_pages_opted_out(e + std::strlen("TISSUE_HUGE_PAGES=")))
      return false;
    if (starts_with(e, "GLIBC_TUNABLES=")) tunables = e + std::strlen("GLIBC_TUNABLES=");
    if (starts_with(e, "LD_PRELOAD=") && std::strstr(e, "vgpreload") != nullptr) return false;
  }
  if (tunables != nullptr && std::strstr(tunables, "glibc.malloc.hugetlb") != nullptr) return false;
  if (under_valgrind || !granted_on_request) return false;
  const char* name = "GLIBC_TUNABLES=";
  const char* add = "glibc.malloc.hugetlb=1";
  const std::size_t old_length = tunables != nullptr ? std::strlen(tunables) : 0;
  if (std::strlen(name) + old_length + 1 + std::strlen(add) + 1 > size) return false;
  std::strcpy(entry, name);
  if (old_length > 0) {
    std::strcat(entry, tunables);
    std::strcat(entry, ":");
  }
  std::strcat(entry, add);
  return true;
}

}  // namespace tissue
