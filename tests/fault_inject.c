/* Fault injection for the fault tests (tests/faults_test.py): an LD_PRELOAD library that makes chosen file system
 * calls of chosen ranks fail as a full disk, an exhausted quota or a failing device does. No privileges needed.
 *
 *   TISSUE_FAULT_CALL   open | write | pwrite | fsync | rename   (write: write, writev; pwrite: pwrite, pwrite64,
 *                       pwritev, pwritev2; open: open/openat/creat for writing; fsync: fsync, fdatasync)
 *   TISSUE_FAULT_ERRNO  ENOSPC | EDQUOT | EIO | SIGKILL         (default ENOSPC; SIGKILL: the process kills itself
 *                       with kill -9 in that call: a rank dying in the middle of a write)
 *   TISSUE_FAULT_RANK   0 | 1 | ... | all                        (OMPI_COMM_WORLD_RANK, or PMI_RANK; none: rank 0)
 *   TISSUE_FAULT_AFTER  write, pwrite: bytes let through first; open, fsync, rename: calls let through first
 *   TISSUE_FAULT_FILE   only calls on files whose path holds this text count and fail (default: every file)
 *   TISSUE_FAULT_LOG    if set, one line "fault: CALL PATH ERRNO" on stderr at the first injected failure
 *
 * A fault is sticky, as a full disk is: once the threshold is passed, every matching call fails. Reads are never
 * touched, so files written before the fault can be read back. Use `mpirun -x LD_PRELOAD=...` so that only the
 * application processes, not mpirun itself, load it. */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <errno.h>
#include <fcntl.h>
#include <signal.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/types.h>
#include <sys/uio.h>
#include <unistd.h>

static int configured = 0, active = 0, fault_errno = ENOSPC, logged = 0;
static char call[16], file_part[512];
static long long after = 0, used = 0;

static void configure(void) {
  if (configured) return;
  configured = 1;
  const char* c = getenv("TISSUE_FAULT_CALL");
  if (!c || !*c) return;
  const char* want = getenv("TISSUE_FAULT_RANK");
  const char* rank = getenv("OMPI_COMM_WORLD_RANK");
  if (!rank) rank = getenv("PMI_RANK");
  if (!rank) rank = "0";
  if (want && strcmp(want, "all") != 0 && strcmp(want, rank) != 0) return;
  snprintf(call, sizeof call, "%s", c);
  const char* e = getenv("TISSUE_FAULT_ERRNO");
  if (e && strcmp(e, "EDQUOT") == 0) fault_errno = EDQUOT;
  else if (e && strcmp(e, "EIO") == 0) fault_errno = EIO;
  else if (e && strcmp(e, "SIGKILL") == 0) fault_errno = -SIGKILL;
  const char* a = getenv("TISSUE_FAULT_AFTER");
  after = a ? atoll(a) : 0;
  const char* f = getenv("TISSUE_FAULT_FILE");
  snprintf(file_part, sizeof file_part, "%s", f ? f : "");
  active = 1;
}

static int path_matches(const char* path) {
  configure();
  return !file_part[0] || (path && strstr(path, file_part)); }

static char fd_path[4096];
static void configure(void);

static int fd_matches(int fd) {
  char link[64];
  configure();
  if (!active) return 0;
  fd_path[0] = 0;
  snprintf(link, sizeof link, "/proc/self/fd/%d", fd);
  const ssize_t n = readlink(link, fd_path, sizeof fd_path - 1);
  fd_path[n > 0 ? n : 0] = 0;
  if (!file_part[0]) return 1;
  return n > 0 && strstr(fd_path, file_part) != NULL;
}

/* Whether this call fails: `amount` bytes (write, pwrite) or 1 (a call) more of what the threshold counts. */
static int inject(const char* name, int matches, long long amount, const char* what) {
  configure();
  if (!active || strcmp(call, name) != 0 || !matches) return 0;
  if (used + amount <= after) {
    used += amount;
    return 0;
  }
  used = after + 1;  /* sticky */
  if (!logged && getenv("TISSUE_FAULT_LOG")) {
    logged = 1;
    fprintf(stderr, "fault: %s %s %s\n", name, what ? what : "",
            fault_errno == -SIGKILL ? "kill -9" : strerror(fault_errno));
  }
  if (fault_errno == -SIGKILL) kill(getpid(), SIGKILL);
  errno = fault_errno;
  return 1;
}

#define REAL(ret, name, ...)                             \
  static ret (*real_##name)(__VA_ARGS__) = NULL;         \
  if (!real_##name) real_##name = (ret(*)(__VA_ARGS__))dlsym(RTLD_NEXT, #name)

static int writing(int flags) { return (flags & (O_WRONLY | O_RDWR | O_CREAT | O_TRUNC)) != 0; }

int open(const char* path, int flags, ...) {
  REAL(int, open, const char*, int, ...);
  mode_t mode = 0;
  if (flags & (O_CREAT | O_TMPFILE)) {
    va_list ap;
    va_start(ap, flags);
    mode = va_arg(ap, mode_t);
    va_end(ap);
  }
  if (writing(flags) && inject("open", path_matches(path), 1, path)) return -1;
  return real_open(path, flags, mode);
}

int open64(const char* path, int flags, ...) {
  REAL(int, open64, const char*, int, ...);
  mode_t mode = 0;
  if (flags & (O_CREAT | O_TMPFILE)) {
    va_list ap;
    va_start(ap, flags);
    mode = va_arg(ap, mode_t);
    va_end(ap);
  }
  if (writing(flags) && inject("open", path_matches(path), 1, path)) return -1;
  return real_open64(path, flags, mode);
}

int openat(int dir, const char* path, int flags, ...) {
  REAL(int, openat, int, const char*, int, ...);
  mode_t mode = 0;
  if (flags & (O_CREAT | O_TMPFILE)) {
    va_list ap;
    va_start(ap, flags);
    mode = va_arg(ap, mode_t);
    va_end(ap);
  }
  if (writing(flags) && inject("open", path_matches(path), 1, path)) return -1;
  return real_openat(dir, path, flags, mode);
}

int creat(const char* path, mode_t mode) {
  REAL(int, creat, const char*, mode_t);
  if (inject("open", path_matches(path), 1, path)) return -1;
  return real_creat(path, mode);
}

ssize_t write(int fd, const void* buf, size_t n) {
  REAL(ssize_t, write, int, const void*, size_t);
  if (n > 0 && inject("write", fd_matches(fd), (long long)n, fd_path)) return -1;
  return real_write(fd, buf, n);
}

static long long iov_bytes(const struct iovec* iov, int count) {
  long long n = 0;
  for (int i = 0; i < count; ++i) n += (long long)iov[i].iov_len;
  return n;
}

ssize_t writev(int fd, const struct iovec* iov, int count) {
  REAL(ssize_t, writev, int, const struct iovec*, int);
  if (inject("write", fd_matches(fd), iov_bytes(iov, count), fd_path)) return -1;
  return real_writev(fd, iov, count);
}

ssize_t pwrite(int fd, const void* buf, size_t n, off_t offset) {
  REAL(ssize_t, pwrite, int, const void*, size_t, off_t);
  if (n > 0 && inject("pwrite", fd_matches(fd), (long long)n, fd_path)) return -1;
  return real_pwrite(fd, buf, n, offset);
}

ssize_t pwrite64(int fd, const void* buf, size_t n, off64_t offset) {
  REAL(ssize_t, pwrite64, int, const void*, size_t, off64_t);
  if (n > 0 && inject("pwrite", fd_matches(fd), (long long)n, fd_path)) return -1;
  return real_pwrite64(fd, buf, n, offset);
}

ssize_t pwritev(int fd, const struct iovec* iov, int count, off_t offset) {
  REAL(ssize_t, pwritev, int, const struct iovec*, int, off_t);
  if (inject("pwrite", fd_matches(fd), iov_bytes(iov, count), fd_path)) return -1;
  return real_pwritev(fd, iov, count, offset);
}

ssize_t pwritev2(int fd, const struct iovec* iov, int count, off_t offset, int flags) {
  REAL(ssize_t, pwritev2, int, const struct iovec*, int, off_t, int);
  if (inject("pwrite", fd_matches(fd), iov_bytes(iov, count), fd_path)) return -1;
  return real_pwritev2(fd, iov, count, offset, flags);
}

int fsync(int fd) {
  REAL(int, fsync, int);
  if (inject("fsync", fd_matches(fd), 1, fd_path)) return -1;
  return real_fsync(fd);
}

int fdatasync(int fd) {
  REAL(int, fdatasync, int);
  if (inject("fsync", fd_matches(fd), 1, fd_path)) return -1;
  return real_fdatasync(fd);
}

int rename(const char* from, const char* to) {
  REAL(int, rename, const char*, const char*);
  if (inject("rename", path_matches(from), 1, from)) return -1;
  return real_rename(from, to);
}

int renameat(int fromdir, const char* from, int todir, const char* to) {
  REAL(int, renameat, int, const char*, int, const char*);
  if (inject("rename", path_matches(from), 1, from)) return -1;
  return real_renameat(fromdir, from, todir, to);
}
