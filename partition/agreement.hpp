// Errors on one rank are errors on every rank (docs/design.md, "Errors on one rank are errors on every rank").
//
// A collective stage (a write, a restart read, the output check) runs its local work inside agree(): whatever the
// work throws on one rank is caught there, every rank learns at the end of the stage whether any rank failed, and
// then every rank throws the SAME exception: the first failing rank's message, with its type kept as far as the
// exit code needs it (InputError stays an InputError: exit 2; anything else becomes an OutputError, or a
// std::runtime_error for non-I/O failures: exit 3). No rank is left waiting in a collective that another rank
// has left.
//
//   agree(comm, [&] { ... this rank's part of the stage, including its collectives ... });
//
// The agreement itself runs on a private duplicate of `comm` (made at the first agree() on that communicator,
// while every rank is at the same point), so it never matches a collective of the stage by mistake. A rank that
// failed waits at most agreement_seconds() (TISSUE_AGREEMENT_SECONDS, default 15) for the others; if they do not
// come (stuck in a collective of the stage, or dead), it prints its one line and ends the job with MPI_Abort:
// the last resort, never a hang.
#pragma once
#include <mpi.h>

#include <exception>
#include <stdexcept>
#include <string>
#include <type_traits>

#include "src/model/scene.hpp"

namespace tissue {

// A file could not be written, synced, renamed or read back (ENOSPC, EDQUOT, EIO, ...): exit 3. The message
// names the file and the system error.
class OutputError : public std::runtime_error {
public:
  explicit OutputError(const std::string& what) : std::runtime_error(what) {}
};

// What agree_on() throws: the agreed failure, already the same on every rank. An enclosing agree() passes it on
// without a second agreement (the other ranks are unwinding too), so stages nest.
struct Agreed {
  virtual ~Agreed() = default;
};

// An exception that every rank throws together by design, because the ranks decided on it from reduced values
// (a SolverFailure of the guards or the static solver). When every rank threw one, agree() lets each rank's own
// exception pass unchanged (its type and what it carries, e.g. the state a SolverFailure left); when only some
// ranks did, it is agreed like any other error.
struct Collective {
  virtual ~Collective() = default;
};

// The exit code a failure maps to: 2 for bad input (InputError), 3 otherwise.
int exit_code_of(const std::exception& e);

// Collective: ends a stage. `error` is what this rank's work threw (null: it succeeded). Returns when no rank
// failed; otherwise throws, on every rank, the first failing rank's exception (same type, same message).
void agree_on(MPI_Comm comm, std::exception_ptr error);

// Collective, at the start of a stage (every rank at the same point): makes the private duplicate of `comm` that
// agree_on() uses, once per communicator; later calls cost nothing. agree() calls it.
void prepare_agreement(MPI_Comm comm);

// Collective: runs this rank's part of a stage and agrees on its outcome (see above). Returns what `work` returns.
template <typename Work>
auto agree(MPI_Comm comm, Work&& work) -> decltype(work()) {
  prepare_agreement(comm);
  std::exception_ptr error;
  if constexpr (std::is_void_v<decltype(work())>) {
    try {
      work();
    } catch (const Agreed&) {
      throw;
    } catch (...) {
      error = std::current_exception();
    }
    agree_on(comm, error);
  } else {
    decltype(work()) result{};
    try {
      result = work();
    } catch (const Agreed&) {
      throw;
    } catch (...) {
      error = std::current_exception();
    }
    agree_on(comm, error);
    return result;
  }
}

// Test hook (tests/faults_test.py): an injected failure on one rank in the middle of a collective stage. When
// TISSUE_FAULT_STAGE names `stage`, the rank TISSUE_FAULT_STAGE_RANK (a number, or "all"; default 1) throws a
// std::runtime_error here after TISSUE_FAULT_STAGE_AFTER calls (default 0) have passed. Without the variable: one
// test of a cached flag.
void fault_point(const char* stage, MPI_Comm comm);

// What the system says when it is asked to write to `file` now (one block past its end, given back at once):
// strerror of the failure ("No space left on device", "Disk quota exceeded", ...), or "" when the write works.
// Used when a write failed inside a library that lost errno (Open MPI's MPI-IO), and at a write's deadline.
std::string probe_write_error(const std::string& file);

// Runs this rank's local work before a reduction and returns what it threw (null: nothing). The agreement then
// costs no collective of its own: the reduction carries a "failed" flag beside its values, and when the reduced
// flag is set every rank calls agree_on(comm, error), which throws the first failing rank's error everywhere.
//
//   std::exception_ptr error = attempt([&] { ... local work ... });
//   double local[3] = {a, b, error ? 1.0 : 0.0}, global[3];
//   MPI_Allreduce(local, global, 3, MPI_DOUBLE, MPI_SUM, comm);
//   if (global[2] > 0) agree_on(comm, error);
template <typename Work>
std::exception_ptr attempt(Work&& work) {
  try {
    work();
  } catch (const Agreed&) {
    throw;
  } catch (...) {
    return std::current_exception();
  }
  return nullptr;
}

// Seconds a failed rank waits for the others at an agreement before it calls MPI_Abort.
double agreement_seconds();

// The bound on a stage whose ranks may be stuck where no agreement can reach them: inside a library's collective
// (parallel HDF5 waits forever in H5Fclose or MPI_File_open when one rank's write or open failed). While a
// StageDeadline lives, a watchdog thread watches the clock. Past the deadline every rank asks the system whether
// it can write `leftover` (the stage's half-written file; probe_write_error()): a rank that cannot is the failed
// one, and after r s (its rank r, up to 8 s: the lowest such rank speaks) it removes `leftover`, prints
// "FILE: cannot write LEFTOVER: SYSTEM ERROR (...did not finish within N s...)" and exits 3, which ends the job
// (the launcher stops the other ranks). A rank whose write works waits 10 s more (r more for rank r > 0, up to
// 8): then rank 0 removes `leftover` and prints "WHAT: the write did not finish within N s ..." without a system
// error, and every rank exits 3. Nested deadlines: the outermost counts. The last resort, never a hang.
class StageDeadline {
public:
  StageDeadline(MPI_Comm comm, const std::string& what, double seconds, const std::string& leftover = "");
  ~StageDeadline();
  StageDeadline(const StageDeadline&) = delete;
  StageDeadline& operator=(const StageDeadline&) = delete;

private:
  bool armed_ = false;
};

// The bound for a stage that writes about `bytes`: TISSUE_STAGE_SECONDS (default 120) plus 1 s per 10 MB.
double stage_seconds(double bytes);

// Last resort, never returns: prints "tissue: MESSAGE" on stderr (this rank) and ends every rank with MPI_Abort
// (exit code `code`).
[[noreturn]] void abort_job(MPI_Comm comm, const std::string& message, int code);

}  // namespace tissue
