#include "io/isolated_parse.hpp"

#include <fcntl.h>
#include <poll.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <stdexcept>
#include <vector>

#include "io/scene.hpp"

namespace tissue {

namespace {

// The child's report: one byte, then the message.
constexpr char kOk = 'O', kInputError = 'E', kOtherError = 'X';
// A verdict longer than this is cut (a crafted attribute quoted in a message can be megabytes).
constexpr std::size_t kMaxMessage = 64 << 10;

void write_all(int fd, const char* data, std::size_t n) {
  while (n > 0) {
    const ssize_t w = ::write(fd, data, n);
    if (w < 0 && errno == EINTR) continue;
    if (w <= 0) return;  // the parent is gone (it killed us or died): nobody to tell
    data += w, n -= static_cast<std::size_t>(w);
  }
}

[[noreturn]] void child(int fd, const std::function<void()>& walk, double timeout_seconds) {
  // Die with the parent, and never outlive the parent's deadline by much, even if the parent is stuck.
  ::prctl(PR_SET_PDEATHSIG, SIGKILL);
  // PETSc's handlers would print a stack and call MPI_Abort (MPI, in the child: forbidden), libFuzzer's alarm handler
  // would report a timeout of the parent's unit, our SIGTERM handler would only set a flag: the defaults let a
  // fault kill the child, which the parent reports. (An ASan build still reports overflows: they are detected
  // before any signal.)
  for (int s : {SIGSEGV, SIGBUS, SIGFPE, SIGILL, SIGABRT, SIGTRAP, SIGSYS, SIGALRM, SIGTERM, SIGINT, SIGPIPE})
    std::signal(s, SIG_DFL);
  ::alarm(static_cast<unsigned>(timeout_seconds) + 5);
  std::string verdict(1, kOk);
  try {
    walk();
  } catch (const InputError& e) {
    verdict = std::string(1, kInputError) + e.what();
  } catch (const std::exception& e) {
    verdict = std::string(1, kOtherError) + e.what();
  } catch (...) {
    verdict = std::string(1, kOtherError) + "unknown exception while parsing";
  }
  write_all(fd, verdict.data(), std::min(verdict.size(), kMaxMessage));
  ::_exit(0);
}

struct Verdict {
  int kind = 0;  // kOk, kInputError, kOtherError
  std::string message;
};

// Rank 0: fork, collect the child's report, reap it, and say what happened.
Verdict run_child(const std::string& path, const std::string& what, const std::function<void()>& walk,
                  double timeout_seconds) {
  int fds[2];
  if (::pipe2(fds, O_CLOEXEC) != 0)
    throw std::runtime_error(path + ": cannot create a pipe to parse the file in a child process: " +
                             std::strerror(errno));
  std::fflush(nullptr);  // else the child's copies of unflushed stdio buffers could be written twice
  const pid_t pid = ::fork();
  if (pid < 0) {
    const int err = errno;
    ::close(fds[0]), ::close(fds[1]);
    throw std::runtime_error(path + ": cannot fork to parse the file in a child process: " + std::strerror(err));
  }
  if (pid == 0) {
    ::close(fds[0]);
    child(fds[1], walk, timeout_seconds);
  }
  ::close(fds[1]);

  std::string report;
  bool timed_out = false;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_seconds);
  std::vector<char> buffer(4096);
  for (;;) {
    const double left = std::chrono::duration<double>(deadline - std::chrono::steady_clock::now()).count();
    if (left <= 0) {
      timed_out = true;
      break;
    }
    pollfd p{fds[0], POLLIN, 0};
    const int ready = ::poll(&p, 1, static_cast<int>(left * 1000) + 1);
    if (ready < 0 && errno == EINTR) continue;  // e.g. SIGTERM: our handler sets a flag, the parse goes on
    if (ready < 0) break;
    if (ready == 0) continue;  // the deadline is checked above
    const ssize_t n = ::read(fds[0], buffer.data(), buffer.size());
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) break;  // end of file: the child has exited or closed its end
    if (report.size() < kMaxMessage) report.append(buffer.data(), static_cast<std::size_t>(n));
  }
  ::close(fds[0]);
  if (timed_out) ::kill(pid, SIGKILL);
  int status = 0;
  pid_t reaped;
  while ((reaped = ::waitpid(pid, &status, 0)) < 0 && errno == EINTR) {
  }

  const std::string refused = "HDF5 could not parse the file (the child process parsing it ";
  const std::string tail = "): corrupt or crafted " + what;
  Verdict v;
  v.kind = kInputError;
  char seconds[32];
  std::snprintf(seconds, sizeof seconds, "%g", timeout_seconds);
  if (timed_out)
    v.message = InputError(path, "", refused + "did not finish within " + seconds + " s" + tail).what();
  else if (reaped == pid && WIFSIGNALED(status))
    v.message = InputError(path, "", refused + "died with signal " + std::to_string(WTERMSIG(status)) + tail).what();
  else if (!report.empty() && (report[0] == kOk || report[0] == kInputError || report[0] == kOtherError) &&
           (reaped != pid || (WIFEXITED(status) && WEXITSTATUS(status) == 0)))
    v.kind = report[0], v.message = report.substr(1);  // (a status taken by someone else's waitpid: the report holds)
  else if (reaped == pid && WIFEXITED(status))
    v.message = InputError(path, "", refused + "exited with status " + std::to_string(WEXITSTATUS(status)) +
                                         " without a verdict" + tail).what();
  else
    v.message = InputError(path, "", refused + "ended without a verdict" + tail).what();
  return v;
}

}  // namespace

void parse_isolated(const std::string& path, const std::string& what, MPI_Comm comm, const std::function<void()>& walk,
                    double timeout_seconds) {
  int rank = 0;
  MPI_Comm_rank(comm, &rank);
  Verdict v;
  if (rank == 0) {
    try {
      v = run_child(path, what, walk, timeout_seconds);
    } catch (const std::exception& e) {  // no pipe or no fork: every rank throws it
      v.kind = kOtherError, v.message = e.what();
    }
  }
  // Every rank stops together, with the same line.
  int head[2] = {v.kind, static_cast<int>(v.message.size())};
  MPI_Bcast(head, 2, MPI_INT, 0, comm);
  v.kind = head[0];
  v.message.resize(static_cast<std::size_t>(head[1]));
  if (head[1] > 0) MPI_Bcast(v.message.data(), head[1], MPI_CHAR, 0, comm);
  if (v.kind == kOk) return;
  if (v.kind == kInputError) {
    // The message names the file already ("PATH: ..."): passed on verbatim.
    const std::string prefix = path + ": ";
    if (v.message.rfind(prefix, 0) == 0) throw InputError(path, "", v.message.substr(prefix.size()));
    throw InputError(path, "", v.message);
  }
  throw std::runtime_error(v.message);
}

}  // namespace tissue
