#!/usr/bin/env bash
# The coordinator in checkpoints: multi_robot_shared to 10 s with a checkpoint every 3 simulated
# seconds, once without stopping and once killed with SIGKILL at step 2600, about 7.4 s (turtlebot_2 slowed
# for turtlebot_1's arm since 6.9 s; the last checkpoint at 6 s) and resumed with `m3dp run
# --resume`. The resumed run must give the same state hash at every step (robots included), and
# the same waiting and slowed times in its summary.
set -euo pipefail
m3dp=$1 scene=$2 out=$3
rm -rf "$out"
mkdir -p "$out"
run=(run "$scene" --until 10 --hash --checkpoint-period 3 --threads 2 --quiet)
"$m3dp" "${run[@]}" -o "$out/whole" > "$out/whole.log"

killed="$out/killed"
"$m3dp" "${run[@]}" -o "$killed" > /dev/null 2>&1 &
pid=$!
for _ in $(seq 1 6000); do
  lines=$({ wc -l < "$killed/hashes.csv.partial"; } 2>/dev/null || echo 0)
  [ "$lines" -gt 2600 ] && break
  sleep 0.01
done
kill -0 $pid 2>/dev/null || { echo "FAIL: the run ended before it could be killed"; exit 1; }
kill -KILL $pid
wait $pid 2>/dev/null || true
"$m3dp" run --resume "$killed" --quiet > "$out/resumed.log"
cmp "$out/whole/hashes.csv" "$killed/hashes.csv" || { echo "FAIL: the state hashes differ"; exit 1; }
/usr/bin/python3 - "$out/whole" "$killed" <<'PY'
import json, sys
whole, resumed = (json.load(open(f"{folder}/summary.json")) for folder in sys.argv[1:])
for a, b in zip(whole["robots"], resumed["robots"]):
    assert a["coordination"] == b["coordination"], (a["name"], a["coordination"], b["coordination"])
    print(a["name"], "waited", a["coordination"]["waiting_time_s"], "s, slowed", a["coordination"]["slowed_time_s"], "s: the same resumed")
assert whole["robots"][1]["coordination"]["slowed_time_s"] > 1, "turtlebot_2 should have slowed by 10 s"
PY
echo "OK: $(wc -l < "$out/whole/hashes.csv") state hashes identical after a kill at step 2600 and a resume from 6 s"
