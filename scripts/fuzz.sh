#!/usr/bin/env bash
# Builds the modules that read users' files (core, material, sph, toolpath, io, scene, world) with
# AddressSanitizer and UndefinedBehaviorSanitizer (clang, build-fuzz/), runs their unit tests under
# them, then fuzzes each reader for SECONDS (default 30) from seeds the project wrote (its scenes,
# URDF robots, G-code, waypoint CSV, and what its mesh and frame writers write) and the corpus of
# earlier runs. Exits non-zero on any finding: libFuzzer leaves the input as build-fuzz/crash-*.
# Usage: scripts/fuzz.sh [SECONDS] [TARGET...]   (make test runs it for 60 s a target)
set -euo pipefail
cd "$(dirname "$0")/.."
seconds=${1:-30}
shift || true
targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=(fuzz_gcode fuzz_waypoints fuzz_mesh fuzz_particles fuzz_scene fuzz_urdf)
build=build-fuzz
if [ ! -f $build/build.ninja ]; then
  CXX=clang++ cmake -S . -B $build -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DM3DP_FUZZ=ON > /dev/null
fi
cmake --build $build -j "$(nproc)" > $build/build.log 2>&1 || { tail -n 30 $build/build.log; exit 1; }

export ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
# The modules' unit tests under the sanitizers (the sliced-profile test is in the main build's suite).
for test in test_gcode test_toolpath test_mesh_io test_kernels test_neighbor_search test_boundary_sampling test_rheology test_scene; do
  $build/$test --gtest_filter=-*RealPrinterProfiles* --gtest_brief=1 > $build/$test.log 2>&1 \
    || { tail -n 40 $build/$test.log; echo "fuzz.sh: $test failed under the sanitizers"; exit 1; }
  echo "sanitizers: $test: $(grep -E '^\[  PASSED  \]' $build/$test.log)"
done

# Seeds: the project's own files, and what its writers write.
seeds=$build/seeds
rm -rf "$seeds" && mkdir -p "$seeds/fuzz_gcode" "$seeds/fuzz_waypoints" "$seeds/fuzz_scene" "$seeds/fuzz_urdf"
cp scenes/gcode/*.gcode "$seeds/fuzz_gcode/"
cp scenes/*.sdf tests/data/*.sdf "$seeds/fuzz_scene/"
find models -name '*.urdf' -exec cp {} "$seeds/fuzz_urdf/" \;
printf 'x,y,z,speed,extrude\n0,0,0.1,0.05,1\n0.1,0,0.1,0.05,1\n0.1,0.1,0.1,0.05,0\n' > "$seeds/fuzz_waypoints/seed.csv"
find scenes tests -name '*.csv' -size -64k -exec cp {} "$seeds/fuzz_waypoints/" \;
$build/fuzz/fuzz_seeds "$seeds/generated"
mv "$seeds/generated/mesh" "$seeds/fuzz_mesh" && mv "$seeds/generated/particles" "$seeds/fuzz_particles"

# One target: its line of result in $build/$target.result, non-zero on a finding.
fuzz_target() {
  local target=$1 log=$build/$1.log max_len=16384
  mkdir -p "$build/corpus/$target"
  # Bytes: enough for every format's structure; G-code's meaning is line by line, and its seed's
  # 7,000 lines would slow each run tenfold.
  [ "$target" = fuzz_gcode ] && max_len=2048
  if (cd $build && ./fuzz/$target -max_total_time="$seconds" -rss_limit_mb=2048 -timeout=10 -max_len=$max_len \
        -print_final_stats=1 "corpus/$target" "seeds/$target") > "$log" 2>&1; then
    runs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log")
    echo "fuzz: $target: $runs inputs in ${seconds} s, no finding" > "$build/$target.result"
  else
    { echo "fuzz: $target: FINDING (input saved as build-fuzz/crash-* or leak-*/oom-*/timeout-*):"
      # The report and its stack, so that a CI log alone says where it failed.
      sed -n '/ERROR\|runtime error\|terminate called\|uncaught/,/SUMMARY/p' "$log" | head -n 60
    } > "$build/$target.result"
    return 1
  fi
}

# As many targets at once as there are cores: each still has its SECONDS of a core.
for target in "${targets[@]}"; do
  rm -f "$build/$target.result"
  while [ "$(jobs -rp | wc -l)" -ge "$(nproc)" ]; do wait -n || true; done
  fuzz_target "$target" &
done
wait || true
status=0
for target in "${targets[@]}"; do
  if [ -f "$build/$target.result" ]; then cat "$build/$target.result"; else echo "fuzz: $target: no result"; status=1; fi
  grep -q FINDING "$build/$target.result" 2>/dev/null && status=1
done
exit $status
