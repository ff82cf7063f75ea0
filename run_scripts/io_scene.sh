# The snapshot-write benchmarks' scene (bench_io.sh, bench_io_cpu.sh): a SIDE^3 face-diagonals box held on z+,
# dynamic with no steps (the rest state is written once, as final.h5), the given output fields. Sourced, not run.
ALL_FIELDS='["positions", "displacements", "velocities", "forces", "connection_strain", "connection_force"]'
io_scene() {  # FILE TITLE SIDE OUTPUT_DIRECTORY FIELDS
  cat > "$1" <<EOF
title = "$2"
[body]
molecules = [$3, $3, $3]
spacing = [0.001, 0.001, 0.001]
topology = "face-diagonals"
material = "ligament"
[[fix]]
face = "z+"
[solver]
kind = "dynamic"
steps = 0
[output]
directory = "$4"
fields = $5
progress = false
EOF
}
