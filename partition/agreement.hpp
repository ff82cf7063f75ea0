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

// Seconds a failed rank waits for the others at an agreement before it calls MPI_Abort.
double agreement_seconds();

// The bound on a stage whose ranks may be stuck where no agreement can reach them: inside a library's collective
// (parallel HDF5 waits forever in H5Fclose or MPI_File_open when one rank's write or open failed). While a
// StageDeadline lives, a watchdog thread watches the clock; past the deadline the rank prints one line ("tissue:
// WHAT did not finish within N s ...") and exits with code 3, which ends the job (the launcher stops the other
// ranks). Rank 0 alone prints and removes `leftover` (the stage's half-written file, if any); rank r > 0 waits r
// extra seconds (up to 8) and exits silently, in case rank 0 is not stuck. Nested deadlines: the outermost
// counts. The last resort, never a hang.
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
