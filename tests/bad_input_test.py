#!/usr/bin/env python3
"""Bad input must fail cleanly: `tissue run` on every scene in tests/bad_scenes, on bad --set overrides and on
files that are missing or not scenes exits with code 2, prints exactly one line on stderr naming the file and
the key, takes under 5 s and leaves no output directory behind.

Each file in tests/bad_scenes starts with `# expect: TEXT`: the text the message must contain (usually the
dotted key)."""
import argparse
import re
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

VALID_SCENE = """title = "a valid scene that the --set cases break"
[body]
molecules = [4, 4, 4]
spacing = [0.1, 0.1, 0.1]
youngs_modulus = 1.0e5

[[fix]]
face = "z+"

[[load]]
face = "z-"
force = [0.0, 0.0, -10.0]
"""


def expected_text(path):
    """The `# expect: TEXT` of a bad scene's first line."""
    with open(path, "rb") as f:
        first = f.readline().decode("utf-8", "replace").strip()
    prefix = "# expect:"
    if not first.startswith(prefix):
        raise SystemExit(f"{path}: the first line must be '# expect: TEXT'")
    return first[len(prefix):].strip()


class Runner:
    def __init__(self, tissue, launcher):
        self.tissue = tissue
        self.launcher = launcher
        self.passed = 0
        self.failed = []

    def check(self, label, scene, expects, extra=(), workdir=None, args=None, petsc=(), output=True):
        """Runs `tissue run SCENE [extra] --output DIR/out [-- PETSC]` (or `tissue ARGS --output DIR/out`; without
        --output when `output` is false) and checks the one-line failure."""
        out = Path(workdir) / "out"
        if args is None:
            args = ["run", str(scene), *extra]
        cmd = self.launcher + [str(self.tissue), *args] + (["--output", str(out)] if output else []) + \
            (["--", *petsc] if petsc else [])
        env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
        # The limit is on the CPU seconds of the process tree (its children are all waited for), not the wall
        # clock: rejecting bad input must not need the solve's work, and a loaded machine must not fail the test.
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        start = time.monotonic()
        try:
            p = subprocess.run(cmd, capture_output=True, timeout=60, env=env)
        except subprocess.TimeoutExpired:
            self.failed.append(f"{label}: did not finish in 60 s")
            return
        elapsed = time.monotonic() - start
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
        stderr = p.stderr.decode("utf-8", "replace")
        lines = stderr.splitlines()
        problems = []
        if p.returncode != 2:
            problems.append(f"exit code {p.returncode}, expected 2")
        if len(lines) != 1 or not lines[0].strip():
            problems.append(f"stderr is {len(lines)} lines, expected exactly one")
        for text in expects:
            if text not in stderr:
                problems.append(f"stderr lacks {text!r}")
        if cpu >= 5:
            problems.append(f"took {cpu:.1f} CPU seconds (limit 5 s; {elapsed:.1f} s wall)")
        self.slowest = max(getattr(self, "slowest", 0.0), cpu)
        if out.exists():
            problems.append(f"left {out} behind")
        if problems:
            self.failed.append(f"{label}: " + "; ".join(problems) + f"\n    command: {' '.join(cmd)}"
                               f"\n    stderr: {stderr.strip()!r}")
        else:
            self.passed += 1
            print(f"ok   {label}: {lines[0]}")


def main():
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--build", required=True, help="the build directory holding the tissue executable")
    parser.add_argument("--source", required=True, help="the source directory (holds tests/bad_scenes)")
    parser.add_argument("--launcher", default="", help="a prefix such as 'mpirun -np 1' (default: none)")
    args = parser.parse_args()

    tissue = Path(args.build) / "tissue"
    if not tissue.is_file():
        print(f"{tissue} does not exist: build it first")
        return 1
    runner = Runner(tissue.resolve(), args.launcher.split())
    source = Path(args.source)
    bad_dir = source / "tests" / "bad_scenes"
    scenes = sorted(bad_dir.glob("*.toml"))
    if len(scenes) < 10:
        print(f"only {len(scenes)} scenes in {bad_dir}")
        return 1

    for scene in scenes:
        with tempfile.TemporaryDirectory() as tmp:
            runner.check(scene.name, scene, [scene.name, expected_text(scene)], workdir=tmp)

    with tempfile.TemporaryDirectory() as tmp:
        valid = Path(tmp) / "valid.toml"
        valid.write_text(VALID_SCENE)
        # (label, overrides, texts the message must contain)
        set_cases = [
            ("unknown key", ["body.foo=1"], ["valid.toml", "body.foo"]),
            ("unknown table", ["solvr.kind=static"], ["valid.toml", "solvr"]),
            ("malformed array", ["body.molecules=[20,20"], ["valid.toml", "body.molecules"]),
            ("wrong type", ["solver.tolerance=small"], ["valid.toml", "solver.tolerance"]),
            ("out of range", ["body.youngs_modulus=-1"], ["valid.toml", "body.youngs_modulus"]),
            ("unknown choice", ["solver.kind=quasistatic"], ["valid.toml", "solver.kind"]),
            ("nan", ["physics.gravity=[0,0,nan]"], ["valid.toml", "physics.gravity"]),
            ("no equals sign", ["body.youngs_modulus"], ["--set", "body.youngs_modulus"]),
            ("empty key", ["=5"], ["--set"]),
            ("empty key part", ["body..density=5"], ["--set", "body..density"]),
            ("index out of range", ["load.3.force=[0,0,1]"], ["--set", "load.3.force"]),
            ("into a scalar", ["body.youngs_modulus.x=1"], ["--set", "body.youngs_modulus.x"]),
            ("fix removed", ["fix=[]"], ["valid.toml", "solver.kind"]),
        ]
        for label, overrides, expects in set_cases:
            extra = [a for o in overrides for a in ("--set", o)]
            runner.check(f"--set {label}", valid, expects, extra=extra, workdir=tmp)

        # the command line itself: unknown options and subcommands, missing arguments
        cli_cases = [
            ("unknown option", ["run", str(valid), "--bogus"], ["--bogus"]),
            ("unknown option with value", ["run", str(valid), "--sett", "body.density=5"], ["--sett"]),
            ("unknown subcommand", ["frobnicate", str(valid)], ["subcommand"]),
            ("run without scene", ["run"], ["scene"]),
            ("--set without value", ["run", str(valid), "--set"], ["--set"]),
            ("restart with a model key", ["restart", str(valid), "--set", "body.density=5"], ["body.density"]),
        ]
        for label, args, expects in cli_cases:
            runner.check(f"cli {label}", None, expects, workdir=tmp, args=args)
        runner.check("cli empty --output", None, ["--output", "empty"], workdir=tmp,
                     args=["run", str(valid), "--output", ""], output=False)

        # the project's own PETSc options (src/solvers/tissue_options.cpp): malformed or out of range
        option_cases = [
            ("-static_enough_fraction", "abc"), ("-static_enough_fraction", "-1"), ("-static_first_rtol", "2"),
            ("-static_chebyshev_fraction", "0"), ("-static_cell_coarse_steps", "-3"),
            ("-static_volume_smoother_steps", "0"), ("-tissue_guards", "maybe"), ("-tissue_fuse_rows", "x"),
            ("-static_fused_chebyshev", "sometimes"),
        ]
        # every -static_* / -tissue_* option the sources read, with a value no option takes (one that a new
        # option's reader forgets to check shows here)
        read = set()
        for path in list(source.glob("src/**/*.cpp")) + list(source.glob("io/*.cpp")):
            read |= set(re.findall(r'"(-(?:static|tissue)_[a-z_]+)"', path.read_text()))
        option_cases += [(name, "x@y") for name in sorted(read)]
        option_cases += [("-static_symbol_upper", "-1"), ("-static_level_one_pull", "maybe")]
        # PETSc's own options, refused by PETSc when the solver reads them (exit 2, one line, nothing written)
        option_cases += [("-ksp_type", "nosuchksp"), ("-pc_type", "nosuchpc"), ("-ksp_rtol", "abc"),
                         ("-options_file", str(Path(tmp) / "no_such_options"))]
        for name, value in option_cases:
            runner.check(f"option {name} {value}", valid, ["PETSc options", name], workdir=tmp, petsc=[name, value])

        runner.check("a device", Path("/dev/zero"), ["/dev/zero", "device"], workdir=tmp)  # read, it never ends
        if "-np" in runner.launcher:  # two ranks given different scenes (MPMD: a stale file on one node alike)
            mpiexec, out = runner.launcher[0], str(Path(tmp) / "out")
            cmd = [mpiexec, "--quiet", "--oversubscribe", "-np", "1", str(runner.tissue), "run", str(valid),
                   "--output", out, ":", "-np", "1", str(runner.tissue), "run", str(valid), "--set",
                   "body.density=5.0", "--output", out]
            p = subprocess.run(cmd, capture_output=True, text=True, timeout=60,
                               env=dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1"))
            lines = p.stderr.strip().splitlines()
            if p.returncode == 2 and len(lines) == 1 and "different scenes" in lines[0] and not Path(out).exists():
                runner.passed += 1
                print(f"ok   ranks given different scenes: {lines[0]}")
            else:
                runner.failed.append(f"ranks given different scenes: exit {p.returncode}, stderr {p.stderr!r}")
        missing = Path(tmp) / "no_such_scene.toml"
        runner.check("missing file", missing, ["no_such_scene.toml"], workdir=tmp)
        directory = Path(tmp) / "a_directory.toml"
        directory.mkdir()
        runner.check("a directory", directory, ["a_directory.toml", "directory"], workdir=tmp)
        empty = Path(tmp) / "truly_empty.toml"
        empty.write_bytes(b"")
        runner.check("empty file", empty, ["truly_empty.toml", "body"], workdir=tmp)
        zeros = Path(tmp) / "zeros.toml"
        zeros.write_bytes(bytes(4096))
        runner.check("NUL bytes", zeros, ["zeros.toml"], workdir=tmp)

    for f in runner.failed:
        print(f"FAIL {f}")
    print(f"{runner.passed} passed, {len(runner.failed)} failed; slowest case {getattr(runner, 'slowest', 0):.2f} CPU seconds")
    if runner.passed + len(runner.failed) < 40:
        print("fewer than 40 cases: the corpus must cover at least 40 malformed scenes and option sets")
        return 1
    return 1 if runner.failed else 0


if __name__ == "__main__":
    sys.exit(main())
