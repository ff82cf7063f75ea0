// The isolated parse (io/isolated_parse.cpp) on walks whose outcome is known in advance: one that succeeds, one
// that refuses, one that really crashes (a write through a null pointer: PETSc's SEGV handler is installed in this
// process, and would call MPI_Abort if the child kept it), one that aborts, one that exits on its own, one that
// hangs. Every rank must see the same outcome; the reference is what the walk does, in its own code. Genuine HDF5
// crash inputs are replayed by fuzz_regressions_test and tests/checkpoint_test.py.
#include <gtest/gtest.h>
#include <mpi.h>
#include <unistd.h>

#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <sstream>
#include <stdexcept>
#include <string>

#include "io/isolated_parse.hpp"
#include "io/scene.hpp"

using namespace tissue;

namespace {

const std::string kPath = "/some/dir/checkpoint_0000000010.h5";

// The exception parse_isolated threw on this rank ("" if none), with its kind.
struct Outcome {
  bool input_error = false, other = false;
  std::string message;
};

Outcome outcome(const std::function<void()>& walk, double timeout = kIsolatedParseSeconds) {
  Outcome o;
  try {
    parse_isolated(kPath, "checkpoint", MPI_COMM_WORLD, walk, timeout);
  } catch (const InputError& e) {
    o.input_error = true, o.message = e.what();
  } catch (const std::exception& e) {
    o.other = true, o.message = e.what();
  }
  return o;
}

// Every rank got the same message.
bool same_on_every_rank(const std::string& message) {
  unsigned long mine[2] = {static_cast<unsigned long>(message.size()), std::hash<std::string>{}(message)};
  unsigned long lo[2], hi[2];
  MPI_Allreduce(mine, lo, 2, MPI_UNSIGNED_LONG, MPI_MIN, MPI_COMM_WORLD);
  MPI_Allreduce(mine, hi, 2, MPI_UNSIGNED_LONG, MPI_MAX, MPI_COMM_WORLD);
  return lo[0] == hi[0] && lo[1] == hi[1];
}

std::string died(const std::string& how) {
  return kPath + ": HDF5 could not parse the file (the child process parsing it " + how +
         "): corrupt or crafted checkpoint";
}

}  // namespace

TEST(IsolatedParse, ASucceedingWalkReturnsOnEveryRank) {
  const Outcome o = outcome([] {});
  EXPECT_FALSE(o.input_error || o.other) << o.message;
  EXPECT_TRUE(same_on_every_rank(o.message));
}

TEST(IsolatedParse, TheWalksInputErrorComesBackVerbatim) {
  const Outcome o = outcome([] { throw InputError(kPath, "kind", "is \"snapshot\", not a checkpoint"); });
  EXPECT_TRUE(o.input_error);
  EXPECT_EQ(o.message, kPath + ": kind: is \"snapshot\", not a checkpoint");
  EXPECT_TRUE(same_on_every_rank(o.message));
}

TEST(IsolatedParse, AnotherExceptionStaysAnotherException) {
  const Outcome o = outcome([] { throw std::runtime_error(kPath + ": /: no attribute kind"); });
  EXPECT_TRUE(o.other);
  EXPECT_FALSE(o.input_error);
  EXPECT_EQ(o.message, kPath + ": /: no attribute kind");
  EXPECT_TRUE(same_on_every_rank(o.message));
}

TEST(IsolatedParse, AChildKilledBySegvIsReportedWithItsSignal) {
  const Outcome o = outcome([] {
    volatile int* nowhere = nullptr;
    *nowhere = 1;  // a genuine invalid write, not raise(): the kernel delivers SIGSEGV
  });
  EXPECT_TRUE(o.input_error);
  EXPECT_EQ(o.message, died("died with signal " + std::to_string(SIGSEGV)));
  EXPECT_EQ(o.message.find('\n'), std::string::npos);
  EXPECT_TRUE(same_on_every_rank(o.message));
}

TEST(IsolatedParse, AnAbortIsASignalToo) {
  const Outcome o = outcome([] { std::abort(); });  // what an ASan report ends in with abort_on_error=1
  EXPECT_EQ(o.message, died("died with signal " + std::to_string(SIGABRT)));
  EXPECT_TRUE(same_on_every_rank(o.message));
}

TEST(IsolatedParse, AnExitWithoutVerdictIsRefusedAndStdioIsNotWrittenTwice) {
  // A library calling exit() in the child would flush the child's copies of the stdio buffers (done here by hand,
  // without exit's atexit handlers, which belong to MPI and HDF5): the parent flushed them before fork, so "once" is
  // written once.
  const std::string file = "isolated_parse_stdio_" + std::to_string(::getpid()) + ".txt";
  std::FILE* f = std::fopen(file.c_str(), "w");
  ASSERT_NE(f, nullptr);
  std::fputs("once", f);  // buffered, not yet written
  const Outcome o = outcome([] {
    std::fflush(nullptr);
    ::_exit(3);
  });
  std::fclose(f);
  std::ifstream in(file);
  std::stringstream text;
  text << in.rdbuf();
  std::remove(file.c_str());
  EXPECT_EQ(text.str(), "once");
  EXPECT_TRUE(o.input_error);
  EXPECT_EQ(o.message, died("exited with status 3 without a verdict"));
  EXPECT_TRUE(same_on_every_rank(o.message));
}

TEST(IsolatedParse, AHangingChildIsKilledAtTheDeadline) {
  const auto start = std::chrono::steady_clock::now();
  const Outcome o = outcome([] { ::sleep(60); }, 0.5);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  EXPECT_EQ(o.message, died("did not finish within 0.5 s"));
  EXPECT_LT(seconds, 20.0);  // 0.5 s and a SIGKILL, on a loaded machine; the walk alone would take 60 s
  EXPECT_TRUE(same_on_every_rank(o.message));
}
