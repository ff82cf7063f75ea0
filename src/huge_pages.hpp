//                  tissue: when the program re-executes itself with glibc's huge pages for malloc
//
// The decision of src/huge_pages.cpp (which says why), apart from the re-execution so that a test can ask it.
// It runs before libc's own initializer: no environ, no stdio, no malloc; the arguments and plain string calls.
#pragma once

#include <cstddef>
#include <cstring>
#include <initializer_list>

namespace tissue {

// `tissue run` re-executes only for scenes of at least this many molecules (src/main.cpp reads the scene first):
// the second start costs each rank 60-110 ms of CPU (the loader's relocations of ~107 libraries), and at 64,000
// molecules on 2 ranks the huge pages already cut the set-up by about 0.1 s a rank; below about 32^3 the whole
// set-up is shorter than the second start (docs/benchmarks.md, branch part18).
constexpr long long kHugePagesFromMolecules = 32768;

// Re-executes the program with the huge-page tunable (the preinit function's work, from main for `tissue run`
// once the scene's size is known), unless huge_pages_entry() or the kernel says no; returns only when it does not.
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
