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
#include <unistd.h>  // defines __GLIBC__ on glibc

#include <cstring>
#include <initializer_list>

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

// Runs before libc's own initializer: no environ, no stdio, no malloc; the arguments and plain system calls only.
bool starts_with(const char* s, const char* prefix) { return std::strncmp(s, prefix, std::strlen(prefix)) == 0; }

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

bool opted_out(const char* value) {
  for (const char* off : {"off", "0", "no", "false"})
    if (std::strcmp(value, off) == 0) return true;
  return false;
}

void reexecute_with_huge_pages(int argc, char** argv, char** envp) {
  if (argc < 2 || argv == nullptr || envp == nullptr) return;
  const char* command = argv[1];
  if (std::strcmp(command, "run") != 0 && std::strcmp(command, "restart") != 0 && std::strcmp(command, "fit") != 0)
    return;
  const char* tunables = nullptr;
  std::size_t count = 0;
  for (; envp[count] != nullptr; ++count) {
    const char* e = envp[count];
    if (starts_with(e, "TISSUE_HUGE_PAGES=") && opted_out(e + std::strlen("TISSUE_HUGE_PAGES="))) return;
    if (starts_with(e, "GLIBC_TUNABLES=")) tunables = e + std::strlen("GLIBC_TUNABLES=");
    if (starts_with(e, "LD_PRELOAD=") && std::strstr(e, "vgpreload") != nullptr) return;  // valgrind
  }
  // Already set: the user's own choice, or this is the re-executed image.
  if (tunables != nullptr && std::strstr(tunables, "glibc.malloc.hugetlb") != nullptr) return;
  if (RUNNING_ON_VALGRIND) return;
  if (!huge_pages_on_request()) return;

  static char entry[4096];
  const char* add = "glibc.malloc.hugetlb=1";
  const std::size_t old_length = tunables != nullptr ? std::strlen(tunables) : 0;
  if (std::strlen("GLIBC_TUNABLES=") + old_length + 1 + std::strlen(add) + 1 > sizeof entry) return;
  std::strcpy(entry, "GLIBC_TUNABLES=");
  if (tunables != nullptr && old_length > 0) {
    std::strcat(entry, tunables);
    std::strcat(entry, ":");
  }
  std::strcat(entry, add);

  char** env = static_cast<char**>(alloca((count + 2) * sizeof(char*)));
  std::size_t k = 0;
  for (std::size_t i = 0; i < count; ++i)
    if (!starts_with(envp[i], "GLIBC_TUNABLES=")) env[k++] = envp[i];
  env[k++] = entry;
  env[k] = nullptr;
  ::execve("/proc/self/exe", argv, env);
  // The re-execution failed (no /proc, say): carry on as started, on 4 kB pages.
}

}  // namespace

// glibc calls the executable's .preinit_array functions with (argc, argv, envp) before any initializer.
__attribute__((section(".preinit_array"), used)) static void (*const tissue_huge_pages)(int, char**, char**) =
    reexecute_with_huge_pages;

#endif
