#include "partition/agreement.hpp"

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
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
  int mine = error ? rank : size, first = size;
  MPI_Request request;
  MPI_Iallreduce(&mine, &first, 1, MPI_INT, MPI_MIN, dup, &request);
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

  // Every rank is here: the first failing rank's kind and message go to all, and all throw the same.
  int header[2] = {kind, static_cast<int>(message.size())};
  MPI_Bcast(header, 2, MPI_INT, first, dup);
  std::vector<char> text(message.begin(), message.end());
  text.resize(static_cast<std::size_t>(header[1]));
  if (header[1] > 0) MPI_Bcast(text.data(), header[1], MPI_CHAR, first, dup);
  throw_kind(header[0], std::string(text.begin(), text.end()));
}

namespace {

// The watchdog of StageDeadline: one thread, started at the first deadline, never joined (it sleeps while no
// deadline is armed).
struct Watchdog {
  std::mutex mutex;
  std::condition_variable changed;
  int depth = 0;
  std::chrono::steady_clock::time_point deadline;
  std::string message, leftover;
  int rank = 0;
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
    if (std::chrono::steady_clock::now() >= w.deadline) {
      if (w.rank == 0) {
        if (!w.leftover.empty()) std::remove(w.leftover.c_str());
        std::fprintf(stderr, "tissue: %s\n", w.message.c_str());
        std::fflush(stderr);
      }
      std::_Exit(3);
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
  w.deadline = std::chrono::steady_clock::now() +
               std::chrono::milliseconds(static_cast<long long>(1000 * (seconds + std::min(rank, 8))));
  w.rank = rank;
  w.leftover = leftover;
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
