//                  tissue: transparent huge pages for malloc, without an environment variable
//
// The set-up of a large sample first-touches gigabytes: on a 4 kB page that is one page fault each, and on a
// virtual machine a fault is microseconds. glibc (2.35 and later) madvises its large allocations for
// transparent huge pages when the tunable glibc.malloc.hugetlb=1 is set, which it reads only at start-up. So the
// program re-executes itself once with the tunable added, before any library initializer has run (a
// .preinit_array function runs before the shared libraries' initializers: the second start costs only the
// dynamic loader's work). Only for the commands that compute (run, restart, fit), only where the kernel gives huge
// pages on request ("[madvise]" in /sys/kernel/mm/transparent_hugepage/enabled: "always" needs no request,
// "never" grants none), never under valgrind (the new image would run outside it) or a sanitizer (it owns
// malloc). Results do not depend on where memory lies. Opt-out: TISSUE_HUGE_PAGES=off (README).

#include <alloca.h>
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>  // defines __GLIBC__ on glibc

#include <cstdlib>
#include <cstring>

#include "src/huge_pages.hpp"

#if defined(__GLIBC__) && (__GLIBC__ > 2 || (__GLIBC__ == 2 && __GLIBC_MINOR__ >= 35))
#define TISSUE_HUGE_PAGES_REEXEC 1
#endif
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#undef TISSUE_HUGE_PAGES_REEXEC
#endif
#if defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer) || __has_feature(memory_sanitizer)
#undef TISSUE_HUGE_PAGES_REEXEC
#endif
#endif

#ifdef TISSUE_HUGE_PAGES_REEXEC

#if __has_include(<valgrind/valgrind.h>)
#include <valgrind/valgrind.h>
#else
#define RUNNING_ON_VALGRIND 0
#endif

namespace {

// "[madvise]" in the kernel's THP mode: huge pages are granted where a mapping asks for them.
bool huge_pages_on_request() {
  const int fd = ::open("/sys/kernel/mm/transparent_hugepage/enabled", O_RDONLY | O_CLOEXEC);
  if (fd < 0) return false;
  char text[128];
  const ssize_t n = ::read(fd, text, sizeof text - 1);
  ::close(fd);
  if (n <= 0) return false;
  text[n] = '\0';
  return std::strstr(text, "[madvise]") != nullptr;
}

}  // namespace

void tissue::reexecute_with_huge_pages(int argc, char** argv, char** envp) {
  static char entry[4096];
  // Cheap checks first: the kernel's mode is a file read.
  if (!tissue::huge_pages_entry(argc, argv, envp, /*granted_on_request=*/true, RUNNING_ON_VALGRIND != 0, entry,
                                sizeof entry))
    return;
  if (!huge_pages_on_request()) return;
  std::size_t count = 0;
  while (envp[count] != nullptr) ++count;
  char** env = static_cast<char**>(alloca((count + 2) * sizeof(char*)));
  std::size_t k = 0;
  for (std::size_t i = 0; i < count; ++i)
    if (std::strncmp(envp[i], "GLIBC_TUNABLES=", 15) != 0) env[k++] = envp[i];
  env[k++] = entry;
  env[k] = nullptr;
  // The binary's own path, not /proc/self/exe: the kernel names the process after the file executed, and "exe"
  // would hide it from `pgrep tissue`, top and the job scripts that signal it by name.
  static char path[4096];
  const ssize_t length = ::readlink("/proc/self/exe", path, sizeof path - 1);
  if (length <= 0) return;
  path[length] = '\0';
  ::execve(path, argv, env);
  // The re-execution failed (no /proc, say): carry on as started, on 4 kB pages.
}

namespace {

// `tissue run`'s scene file (the first argument that is not an option or an option's value) read whole into
// text when it is a plain file of at most size - 1 bytes; false otherwise (a pipe is not opened: it is read once).
bool read_run_scene(int argc, char** argv, char* text, std::size_t size) {
  const char* path = nullptr;
  for (int i = 2; i < argc && argv[i] != nullptr && path == nullptr; ++i) {
    const char* a = argv[i];
    if (std::strcmp(a, "--") == 0) return false;
    if (std::strcmp(a, "--set") == 0 || std::strcmp(a, "--output") == 0) ++i;
    else if (a[0] != '-') path = a;
  }
  struct stat st;
  if (path == nullptr || ::stat(path, &st) != 0 || !S_ISREG(st.st_mode) || static_cast<std::size_t>(st.st_size) >= size)
    return false;
  const int fd = ::open(path, O_RDONLY | O_CLOEXEC);
  if (fd < 0) return false;
  std::size_t got = 0;
  for (ssize_t n; got < size - 1 && (n = ::read(fd, text + got, size - 1 - got)) > 0;) got += static_cast<std::size_t>(n);
  ::close(fd);
  text[got] = '\0';
  return true;
}

// glibc 2.35-2.37 reads the kernel's mode ("always [madvise] never\n", 23 bytes) into a 24-byte stack buffer and
// strcmp()s it unterminated: the tunable takes effect only when the stack byte after the text happens to be 0,
// which it was not in 6 of 10 starts of this program (each such rank then first-touches its ~400 MB on 4 kB
// pages: the static 10^6 solve's "slow state", docs/benchmarks.md, branch static18t). So malloc is initialized
// here, before anything else allocates, from a frame laid over stack bytes just set to 0.
[[gnu::noinline]] void zero_stack_below() {
  volatile char bytes[16384];
  for (std::size_t i = 0; i < sizeof bytes; ++i) bytes[i] = 0;
}
[[gnu::noinline]] void initialize_malloc() {
  void* volatile first = std::malloc(1);
  std::free(first);
}
void initialize_malloc_on_zeroed_stack(char** envp) {
  for (std::size_t i = 0; envp != nullptr && envp[i] != nullptr; ++i)
    if (std::strncmp(envp[i], "GLIBC_TUNABLES=", 15) == 0 && std::strstr(envp[i], "glibc.malloc.hugetlb") != nullptr) {
      zero_stack_below();
      initialize_malloc();
      return;
    }
}

// Before any library initializer: `restart` and `fit` re-execute; `run` only when its scene is not known to be
// smaller than kHugePagesFromMolecules (the second start costs more than the huge pages save on a small scene).
void reexecute_before_initializers(int argc, char** argv, char** envp) {
  initialize_malloc_on_zeroed_stack(envp);
  if (argc >= 2 && argv != nullptr && argv[1] != nullptr && std::strcmp(argv[1], "run") == 0) {
    static char text[1 << 16];
    const long long n = tissue::scanned_molecules(argc, argv, read_run_scene(argc, argv, text, sizeof text) ? text : nullptr);
    if (n >= 0 && n < tissue::kHugePagesFromMolecules) return;
  }
  tissue::reexecute_with_huge_pages(argc, argv, envp);
}

}  // namespace

// glibc calls the executable's .preinit_array functions with (argc, argv, envp) before any initializer.
__attribute__((section(".preinit_array"), used)) static void (*const tissue_huge_pages)(int, char**, char**) =
    reexecute_before_initializers;

#else

void tissue::reexecute_with_huge_pages(int, char**, char**) {}

#endif
