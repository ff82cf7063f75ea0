// partition/agreement: an error on one rank is the same error, of the same kind, on every rank (docs/design.md,
// "Errors on one rank are errors on every rank"); agreed errors pass through enclosing stages; the output location
// check (io/output_location) refuses bad directories on every rank and leaves nothing behind.
#include <gtest/gtest.h>
#include <mpi.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <string>

#include "io/atomic_file.hpp"
#include "io/output_location.hpp"
#include "partition/agreement.hpp"

using namespace tissue;
namespace fs = std::filesystem;

namespace {

int comm_rank() {
  int r;
  MPI_Comm_rank(MPI_COMM_WORLD, &r);
  return r;
}

int comm_size() {
  int s;
  MPI_Comm_size(MPI_COMM_WORLD, &s);
  return s;
}

// What agree() threw on this rank: "input", "output", "other" or "none", and the message.
template <typename Work>
std::pair<std::string, std::string> outcome(Work&& work) {
  try {
    agree(MPI_COMM_WORLD, work);
  } catch (const InputError& e) {
    return {"input", e.what()};
  } catch (const OutputError& e) {
    return {"output", e.what()};
  } catch (const std::exception& e) {
    return {"other", e.what()};
  }
  return {"none", ""};
}

}  // namespace

TEST(Agreement, SuccessReturnsTheValue) {
  EXPECT_EQ(agree(MPI_COMM_WORLD, [] { return comm_rank() + 1; }), comm_rank() + 1);
}

TEST(Agreement, OneRankFailsEveryRankThrowsTheSameKindAndMessage) {
  const int last = comm_size() - 1;
  auto input = outcome([&] {
    if (comm_rank() == last) throw InputError("scene.toml", "output.directory", "bad");
  });
  EXPECT_EQ(input.first, "input");
  EXPECT_EQ(input.second, "scene.toml: output.directory: bad");
  auto output = outcome([&] {
    if (comm_rank() == last) throw OutputError("out/final.h5: cannot write: No space left on device");
  });
  EXPECT_EQ(output.first, "output");
  EXPECT_EQ(output.second, "out/final.h5: cannot write: No space left on device");
  auto other = outcome([&] {
    if (comm_rank() == 0) throw std::invalid_argument("rank 0 says no");
  });
  EXPECT_EQ(other.first, "other");
  EXPECT_EQ(other.second, "rank 0 says no");
}

TEST(Agreement, TheLowestFailingRankSpeaks) {
  auto r = outcome([&] { throw OutputError("from rank " + std::to_string(comm_rank())); });
  EXPECT_EQ(r.first, "output");
  EXPECT_EQ(r.second, "from rank 0");
}

TEST(Agreement, AgreedErrorsPassThroughEnclosingStagesOnce) {
  // The inner stage fails on the last rank; every rank unwinds through the outer stage without a second
  // agreement (a second one would pair with the next test's and mix them up).
  int outer_caught = 0;
  auto r = outcome([&] {
    try {
      agree(MPI_COMM_WORLD, [&] {
        if (comm_rank() == comm_size() - 1) throw OutputError("inner");
      });
    } catch (const Agreed&) {
      outer_caught = 1;
      throw;
    }
  });
  EXPECT_EQ(outer_caught, 1);
  EXPECT_EQ(r.first, "output");
  EXPECT_EQ(r.second, "inner");
  EXPECT_EQ(agree(MPI_COMM_WORLD, [] { return 7; }), 7);  // the agreements still pair up
}

TEST(OutputLocation, RefusesBadDirectoriesOnEveryRankAndLeavesNothing) {
  Scene scene;
  scene.file = "scene.toml";
  scene.body.molecules = {4, 4, 4};
  scene.bodies = {scene.body};
  const std::string base = fs::temp_directory_path().string() + "/tissue_agreement_test";
  if (comm_rank() == 0) {
    fs::remove_all(base);
    fs::create_directories(base);
    write_file_atomically(base + "/a_file", "in the way\n");
  }
  MPI_Barrier(MPI_COMM_WORLD);
  for (const std::string dir : {std::string("/proc/tissue_out"), base + "/a_file", base + "/a_file/out"}) {
    scene.output.directory = dir;
    try {
      check_output_location(scene, MPI_COMM_WORLD);
      ADD_FAILURE() << dir << " accepted";
    } catch (const InputError& e) {
      const std::string what = e.what();
      EXPECT_NE(what.find("scene.toml: output.directory: \"" + dir + "\""), std::string::npos) << what;
    }
  }
  // A new directory (two levels) is accepted, probed by every rank, and removed again.
  scene.output.directory = base + "/new/out";
  EXPECT_NO_THROW(check_output_location(scene, MPI_COMM_WORLD));
  MPI_Barrier(MPI_COMM_WORLD);
  EXPECT_FALSE(fs::exists(base + "/new"));
  // An existing directory stays, without probe files.
  scene.output.directory = base;
  EXPECT_NO_THROW(check_output_location(scene, MPI_COMM_WORLD));
  MPI_Barrier(MPI_COMM_WORLD);
  int entries = 0;
  for (const auto& e : fs::directory_iterator(base)) entries += e.path().filename() != "a_file";
  EXPECT_EQ(entries, 0);
  // No room for the first file: 10^12 molecules do not fit anywhere.
  scene.body.molecules = {10000, 10000, 10000};
  scene.bodies = {scene.body};
  try {
    check_output_location(scene, MPI_COMM_WORLD);
    ADD_FAILURE() << "10^12 molecules fit";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("free; the first snapshot needs about"), std::string::npos) << e.what();
  }
  MPI_Barrier(MPI_COMM_WORLD);
  if (comm_rank() == 0) fs::remove_all(base);
}

namespace {

// An error that every rank throws together, carrying something of its own (as SolverFailure carries its state).
struct Together : std::runtime_error, Collective {
  Together(const std::string& what, int payload) : std::runtime_error(what), payload(payload) {}
  int payload;
};

}  // namespace

TEST(Agreement, ACollectiveErrorOfEveryRankPassesUnchanged) {
  // Every rank throws a Collective: each keeps its own, type and payload (here: its rank), through two stages.
  try {
    agree(MPI_COMM_WORLD, [&] {
      agree(MPI_COMM_WORLD, [&] { throw Together("together", comm_rank()); });
    });
    ADD_FAILURE() << "nothing thrown";
  } catch (const Together& e) {
    EXPECT_EQ(e.payload, comm_rank());
    EXPECT_STREQ(e.what(), "together");
  }
  // Only the last rank throws it: then it is agreed like any other error, and no rank gets a Together (at one
  // rank, every rank threw it: it passes).
  const int last = comm_size() - 1;
  std::string kind = "none", message;
  try {
    agree(MPI_COMM_WORLD, [&] {
      if (comm_rank() == last) throw Together("alone", 7);
    });
  } catch (const Together& e) {
    kind = "together", message = e.what();
  } catch (const std::exception& e) {
    kind = "other", message = e.what();
  }
  EXPECT_EQ(kind, comm_size() > 1 ? "other" : "together");
  EXPECT_EQ(message, "alone");
}

TEST(Agreement, AFlagInAReductionAgreesWithoutACollectiveOfItsOwn) {
  const int last = comm_size() - 1;
  for (int failing : {-1, last}) {
    double local[2] = {1.0, 0.0}, global[2];
    const std::exception_ptr error = attempt([&] {
      if (comm_rank() == failing) throw OutputError("rank " + std::to_string(failing) + " failed");
    });
    local[1] = error ? 1.0 : 0.0;
    MPI_Allreduce(local, global, 2, MPI_DOUBLE, MPI_SUM, MPI_COMM_WORLD);
    EXPECT_EQ(global[0], comm_size());  // the values are reduced as usual
    std::string kind = "none", message;
    try {
      if (global[1] > 0) agree_on(MPI_COMM_WORLD, error);
    } catch (const OutputError& e) {
      kind = "output", message = e.what();
    }
    EXPECT_EQ(kind, failing < 0 ? "none" : "output");
    if (failing >= 0) EXPECT_EQ(message, "rank " + std::to_string(last) + " failed");
  }
}

TEST(Agreement, TheFaultPointThrowsOnTheChosenRankOnly) {
  // The hook reads its variables once, at its first call: this is the first in this program.
  const int last = comm_size() - 1;
  setenv("TISSUE_FAULT_STAGE", "agreement_test", 1);
  setenv("TISSUE_FAULT_STAGE_RANK", std::to_string(last).c_str(), 1);
  setenv("TISSUE_FAULT_STAGE_AFTER", "1", 1);
  EXPECT_NO_THROW(fault_point("another_stage", MPI_COMM_WORLD));
  EXPECT_NO_THROW(fault_point("agreement_test", MPI_COMM_WORLD));  // the one call let through
  auto r = outcome([&] { fault_point("agreement_test", MPI_COMM_WORLD); });
  EXPECT_EQ(r.first, "other");
  EXPECT_EQ(r.second, "injected failure in stage agreement_test on rank " + std::to_string(last) +
                          " (TISSUE_FAULT_STAGE)");
  unsetenv("TISSUE_FAULT_STAGE");
}

TEST(Agreement, TheWriteProbeNamesTheSystemError) {
  // /dev/full fails every write with ENOSPC, as a full disk does; a writable file passes and keeps its size.
  EXPECT_EQ(probe_write_error("/dev/full"), std::strerror(ENOSPC));
  const std::string file = "agreement_probe_" + std::to_string(comm_rank()) + ".bin";
  {
    std::FILE* f = std::fopen(file.c_str(), "w");
    ASSERT_NE(f, nullptr);
    std::fputs("12345", f);
    std::fclose(f);
  }
  EXPECT_EQ(probe_write_error(file), "");
  EXPECT_EQ(fs::file_size(file), 5u);
  EXPECT_EQ(probe_write_error(file + ".missing"), "");  // nothing to probe: no answer
  fs::remove(file);
}
