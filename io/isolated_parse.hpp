// Parsing an untrusted file in a child process: HDF5 1.10 trusts the metadata it decodes, and a crafted file (with
// a valid seal) can make it read past a buffer or crash (issue #8: H5Aexists on a mutated attribute message). Before
// a reader opens such a file, rank 0 forks; the child walks the metadata the reader will touch and reports OK or
// its first problem through a pipe. A child that dies (a signal, an ASan abort), exits without a verdict or takes
// too long turns into one InputError line; the parent never parsed the file, so it survives to print it.
//
// The child makes no MPI calls (Open MPI does not support them after fork) and leaves through _exit, so that the
// parent's stdio buffers (flushed before the fork) and atexit handlers do not run twice.
#pragma once
#include <mpi.h>

#include <functional>
#include <string>

namespace tissue {

// How long the child may take. A metadata walk takes milliseconds; this is for a file that sends HDF5 into a loop.
constexpr double kIsolatedParseSeconds = 60.0;

// Collective over `comm`. Runs `walk` in a child process forked by rank 0 (the other ranks wait for its verdict)
// and returns when it succeeded. Otherwise every rank throws the same exception:
//  - the walk threw InputError: InputError with its message (one line naming the file, as the walk wrote it);
//  - the walk threw another exception: std::runtime_error with its message;
//  - the child died by signal N: InputError "PATH: HDF5 could not parse the file (the child process parsing it died
//    with signal N): corrupt or crafted WHAT"; likewise when it exited without a verdict or ran past
//    `timeout_seconds` (then it is killed).
// `walk` runs in the child only: it must not call MPI (open the file with Hdf5File::open_serial). It may allocate
// and throw (glibc's malloc is fork-safe; MPI's and PETSc's threads are not used). std::runtime_error if fork fails.
void parse_isolated(const std::string& path, const std::string& what, MPI_Comm comm, const std::function<void()>& walk,
                    double timeout_seconds = kIsolatedParseSeconds);

}  // namespace tissue
