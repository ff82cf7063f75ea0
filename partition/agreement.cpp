#include "partition/agreement.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <mutex>
#include <thread>
#include <vector>

namespace tissue {

namespace {

// The private duplicate of a communicator, cached on it as an MPI attribute (freed with it).
int keyval = MPI_KEYVAL_INVALID;

int free_duplicate(MPI_Comm, int, void* value, void*) {
  MPI_Comm* dup = static_cast<MPI_Comm*>(value);
  MPI_Comm_free(dup);
  delete dup;
  return MPI_SUCCESS;
}

MPI_Comm cached_duplicate(MPI_Comm comm) {
  if (keyval == MPI_KEYVAL_INVALID) return MPI_COMM_NULL;
  void* value = nullptr;
  int found = 0;
  MPI_Comm_get_attr(comm, keyval, &value, &found);
  return found ? *static_cast<MPI_Comm*>(value) : MPI_COMM_NULL;
}

enum Kind : int { kOther = 1, kInput = 2, kOutput = 3 };

// What this rank's failure is, as a kind and a message.
Kind classify(std::exception_ptr error, std::string& message) {
  try {
    std::rethrow_exception(error);
  } catch (const InputError& e) {
    message = e.what();
    return kInput;
  } catch (const OutputError& e) {
    message = e.what();
    return kOutput;
  } catch (const std::exception& e) {
    message = e.what();
    return kOther;
  } catch (...) {
    message = "unknown error";
    return kOther;
  }
}

struct AgreedInputError : InputError, Agreed {
  using InputError::InputError;
};
struct AgreedOutputError : OutputError, Agreed {
  using OutputError::OutputError;
};
struct AgreedError : std::runtime_error, Agreed {
  using std::runtime_error::runtime_error;
};

[[noreturn]] void throw_kind(int kind, const std::string& message) {
  if (kind == kInput) {
    // InputError formats "FILE: KEY: PROBLEM"; split the agreed text so that the message is kept exactly.
    const std::size_t colon = message.find(": ");
    if (colon == std::string::npos) throw AgreedInputError(message, "", "");
    throw AgreedInputError(message.substr(0, colon), "", message.substr(colon + 2));
  }
  if (kind == kOutput) throw AgreedOutputError(message);
  throw AgreedError(message);
}

}  // namespace

int exit_code_of(const std::exception& e) { return dynamic_cast<const InputError*>(&e) ? 2 : 3; }

double agreement_seconds() {
  static const double seconds = [] {
    const char* s = std::getenv("TISSUE_AGREEMENT_SECONDS");
    const double v = s ? std::atof(s) : 0.0;
    return v > 0 ? v : 15.0;
  }();
  return seconds;
}

void prepare_agreement(MPI_Comm comm) {
  if (cached_duplicate(comm) != MPI_COMM_NULL) return;
  if (keyval == MPI_KEYVAL_INVALID) MPI_Comm_create_keyval(MPI_COMM_NULL_COPY_FN, free_duplicate, &keyval, nullptr);
  MPI_Comm* dup = new MPI_Comm;
  MPI_Comm_dup(comm, dup);
  MPI_Comm_set_attr(comm, keyval, dup);
}

void abort_job(MPI_Comm comm, const std::string& message, int code) {
  std::fprintf(stderr, "tissue: %s\n", message.c_str());
  std::fflush(stderr);
  MPI_Abort(comm, code);
  std::_Exit(code);
}

void agree_on(MPI_Comm comm, std::exception_ptr error) {
  prepare_agreement(comm);  // a no-op unless the stage skipped it (then every rank must be here together)
  const MPI_Comm dup = cached_duplicate(comm);
  int rank = 0, size = 1;
  MPI_Comm_rank(dup, &rank);
  MPI_Comm_size(dup, &size);
  std::string message;
  const int kind = error ? classify(error, message) : 0;

  // Which rank failed first (the lowest failing rank; size when none did). A failed rank waits a bounded time:
  // the others may be stuck in a collective of the stage that it left.
  // With it, whether every rank threw a Collective (see agreement.hpp): then each passes its own on.
  bool collective = false;
  if (error) try {
      std::rethrow_exception(error);
    } catch (const Collective&) {
      collective = true;
    } catch (...) {
    }
  int mine[2] = {error ? rank : size, collective ? 1 : 0}, reduced[2] = {size, 0};
  int& first = reduced[0];
  MPI_Request request;
  MPI_Iallreduce(mine, reduced, 2, MPI_INT, MPI_MIN, dup, &request);
  const double deadline = MPI_Wtime() + agreement_seconds();
  for (int done = 0;;) {
    MPI_Test(&request, &done, MPI_STATUS_IGNORE);
    if (done) break;
    if (error && MPI_Wtime() > deadline)
      abort_job(comm, message + " (rank " + std::to_string(rank) + "; the other ranks did not reach the agreement " +
                          "within " + std::to_string(static_cast<int>(agreement_seconds())) + " s: job aborted)",
                kind == kInput ? 2 : 3);
    usleep(200);
  }
  if (first == size) return;
  if (reduced[1] == 1) std::rethrow_exception(error);  // every rank threw a Collective: each keeps its own

  // Every rank is here: the first failing rank's kind and message go to all, and all throw the same.
  int header[2] = {kind, static_cast<int>(message.size())};
  MPI_Bcast(header, 2, MPI_INT, first, dup);
  std::vector<char> text(message.begin(), message.end());
  text.resize(static_cast<std::size_t>(header[1]));
  if (header[1] > 0) MPI_Bcast(text.data(), header[1], MPI_CHAR, first, dup);
  throw_kind(header[0], std::string(text.begin(), text.end()));
}

void fault_point(const char* stage, MPI_Comm comm) {
  static const char* wanted = std::getenv("TISSUE_FAULT_STAGE");
  if (!wanted || std::strcmp(wanted, stage) != 0) return;
  static long calls = 0;
  static const long after = [] {
    const char* a = std::getenv("TISSUE_FAULT_STAGE_AFTER");
    return a ? std::atol(a) : 0L;
  }();
  if (calls++ < after) return;
  const char* who = std::getenv("TISSUE_FAULT_STAGE_RANK");
  int rank = 0;
  MPI_Comm_rank(comm, &rank);
  if (who && std::strcmp(who, "all") == 0) who = nullptr;
  else if (std::atoi(who ? who : "1") != rank) return;
  throw std::runtime_error(std::string("injected failure in stage ") + stage + " on rank " + std::to_string(rank) +
                           " (TISSUE_FAULT_STAGE)");
}

std::string probe_write_error(const std::string& file) {
  // One block past the end, then the size given back: the file's content is untouched. A block, not a byte: a
  // full disk may still have room in the file's last block.
  const int fd = ::open(file.c_str(), O_WRONLY | O_CLOEXEC);
  if (fd < 0) return errno == ENOENT ? "" : std::strerror(errno);
  struct stat st;
  int err = 0;
  if (::fstat(fd, &st) == 0) {
    static const char block[4096] = {0};
    const off_t end = st.st_size + 4096 - st.st_size % 4096;
    if (::pwrite(fd, block, sizeof block, end) != static_cast<ssize_t>(sizeof block)) err = errno ? errno : EIO;
    else if (::fsync(fd) != 0) err = errno;
    if (::ftruncate(fd, st.st_size) != 0 && !err) err = errno;
  }
  ::close(fd);
  return err ? std::strerror(err) : "";
}

namespace {

// The watchdog of StageDeadline: one thread, started at the first deadline, never joined (it sleeps while no
// deadline is armed).
struct Watchdog {
  std::mutex mutex;
  std::condition_variable changed;
  int depth = 0;
  std::chrono::steady_clock::time_point deadline;
  std::string message, leftover, what;
  double seconds = 0;
  int rank = 0;
  bool expired = false;  // past the deadline: the ranks are being told apart (see StageDeadline)
  bool started = false;
};

Watchdog& watchdog() {
  static Watchdog* w = new Watchdog;  // never destroyed: the thread may outlive static destruction
  return *w;
}

void watch() {
  Watchdog& w = watchdog();
  std::unique_lock<std::mutex> lock(w.mutex);
  for (;;) {
    if (w.depth == 0) {
      w.changed.wait(lock);
      continue;
    }
    if (std::chrono::steady_clock::now() >= w.deadline && w.expired) {
      // Grace over: no rank found a system error (or it could not end the job).
      if (w.rank == 0) {
        if (!w.leftover.empty()) std::remove(w.leftover.c_str());
        std::fprintf(stderr, "tissue: %s\n", w.message.c_str());
        std::fflush(stderr);
      }
      std::_Exit(3);
    }
    if (std::chrono::steady_clock::now() >= w.deadline) {
      // The deadline: the rank that cannot write the file names the system's error (the lowest such rank first).
      w.expired = true;
      const std::string error = w.leftover.empty() ? "" : probe_write_error(w.leftover);
      if (!error.empty()) {
        const std::string what = w.what, leftover = w.leftover;
        const int rank = w.rank;
        const long long seconds = static_cast<long long>(w.seconds);
        lock.unlock();
        std::this_thread::sleep_for(std::chrono::seconds(std::min(rank, 8)));
        std::remove(leftover.c_str());
        std::fprintf(stderr, "tissue: %s: cannot write %s: %s (rank %d; the write did not finish within %lld s: "
                             "job ended)\n", what.c_str(), leftover.c_str(), error.c_str(), rank, seconds);
        std::fflush(stderr);
        std::_Exit(3);
      }
      w.deadline += std::chrono::seconds(10 + std::min(w.rank, 8));
      continue;
    }
    w.changed.wait_until(lock, w.deadline);
  }
}

}  // namespace

double stage_seconds(double bytes) {
  static const double base = [] {
    const char* s = std::getenv("TISSUE_STAGE_SECONDS");
    const double v = s ? std::atof(s) : 0.0;
    return v > 0 ? v : 120.0;
  }();
  return base + bytes / 1e7;
}

StageDeadline::StageDeadline(MPI_Comm comm, const std::string& what, double seconds, const std::string& leftover) {
  int rank = 0;
  MPI_Comm_rank(comm, &rank);
  Watchdog& w = watchdog();
  std::lock_guard<std::mutex> lock(w.mutex);
  armed_ = true;
  if (w.depth++ > 0) return;
  w.deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(static_cast<long long>(1000 * seconds));
  w.expired = false;
  w.rank = rank;
  w.leftover = leftover;
  w.what = what;
  w.seconds = seconds;
  w.message = what + ": the write did not finish within " + std::to_string(static_cast<long long>(seconds)) +
              " s (a rank is stuck in a collective: an I/O error on one rank can leave parallel HDF5 waiting " +
              "forever): job ended";
  if (!w.started) {
    w.started = true;
    std::thread(watch).detach();
  }
  w.changed.notify_all();
}

StageDeadline::~StageDeadline() {
  if (!armed_) return;
  Watchdog& w = watchdog();
  std::lock_guard<std::mutex> lock(w.mutex);
  --w.depth;
  w.changed.notify_all();
}

}  // namespace tissue
