#!/bin/bash
# The hostile inputs of issue 59 against `cargo xtask` (hil, wcet, size): for each, the exit
# status, the wall time and peak memory (/usr/bin/time) and the first line on stderr. Bad input
# ends in status 2 with one line at once; a run that cannot hold its checks in 1, promptly;
# never 101 (a panic). The committed inputs a case edits (the loop annotations, the budget,
# the size snapshot, README.md) are put back when it ends, whatever ends it.
#   bash scripts/hostile-xtask.sh          # the cases refused before anything is built
#   SLOW=1 bash scripts/hostile-xtask.sh   # and those that build the Pico image and run it
set -u
root=$(cd "$(dirname "$0")/.." && pwd)
X="cargo xtask"
work=$(mktemp -d)
kept=$work/kept
mkdir "$kept"
restore() {
    for f in "$kept"/*; do
        [ -e "$f" ] && cp "$f" "$root/$(basename "$f" | tr '%' '/')"
    done
    rm -rf "$work"
}
trap restore EXIT
# Keeps a committed file to put back at the end.
keep() { [ -e "$kept/${1//\//%}" ] || cp "$root/$1" "$kept/${1//\//%}"; }
put_back() { cp "$kept/${1//\//%}" "$root/$1"; }
cd "$root"
t() {
    local label="$1"
    shift
    # A hang is cut at 15 minutes (status 124); a crash by a signal shows as such.
    /usr/bin/time -o "$work/tm" -f "%e s %M KB" timeout 900 bash -c "$*" >"$work/out" 2>"$work/err"
    local status=$?
    if grep -q 'terminated by signal' "$work/tm"; then
        status="killed ($(grep -o 'signal [0-9]*' "$work/tm"))"
    fi
    printf '%-5s status %s  %s  %s\n' "$label" "$status" "$(tail -1 "$work/tm")" \
        "$(grep -v -e '^ *Finished' -e '^ *Running' -e '^ *Compiling' -e '^ *Blocking' "$work/err" | head -1 | cut -c1-220)"
}
quiet=$root/scenarios/quiet.json
fault() {
    printf '{"name": "f", "scenario": "%s", %s}' "$quiet" "$2" >"$work/$1"
}
# Fault files: refused at once (2). Item 4: an interval of 2^64-1 us; 13: stops_within_ms on a
# fault played on the pins; 25: no expect; 27: a negative gap, an empty log line,
# motors_off_first on a hang; 24: a duplicate key, a byte order mark.
fault every.json '"fault": {"kind": "bumper-chatter", "at_s": 1, "for_s": 2, "every_us": 18446744073709551615}, "expect": {}'
t 4 "$X hil $work/every.json"
fault within.json '"fault": {"kind": "no-echo", "at_s": 1}, "expect": {"stops_within_ms": 500, "still": true}'
t 13 "$X hil $work/within.json"
fault noexpect.json '"fault": {"kind": "hang", "at_s": 1}'
t 25 "$X hil $work/noexpect.json"
fault gap.json '"fault": {"kind": "hang", "at_s": 1}, "expect": {"sample_gap_max_ms": {"sonar": -5}}'
t 27 "$X hil $work/gap.json"
fault log.json '"fault": {"kind": "hang", "at_s": 1}, "expect": {"log": [""]}'
t 27 "$X hil $work/log.json"
fault first.json '"fault": {"kind": "hang", "at_s": 1}, "expect": {"motors_off_first": true}'
t 27 "$X hil $work/first.json"
fault twice.json '"fault": {"kind": "hang", "at_s": 1, "at_s": 9}, "expect": {}'
t 24 "$X hil $work/twice.json"
printf '\xef\xbb\xbf' | cat - "$root/boards/faults/hang.json" >"$work/bom.json"
t 24 "$X hil $work/bom.json"
# The committed budget (item 2: costs that overflow its margin; 11: a margin of 0 or 10,000 %):
# refused before anything is built (2).
B=boards/pico/bench-budget.json
keep $B
sed 's/"deciding": [0-9]*/"deciding": 18446744073709551615/' "$kept/${B//\//%}" >"$root/$B"
t 2 "$X hil $quiet"
t 2 "$X wcet"
for margin in 0 10000; do
    sed "s/\"margin_percent\": [0-9]*/\"margin_percent\": $margin/" "$kept/${B//\//%}" >"$root/$B"
    t 11 "$X hil $quiet"
done
put_back $B
# The loop annotations (item 9: a key twice; 10: an empty reason on a length; 23: a job
# mistyped): refused before the image is built (2).
L=boards/pico/wcet-loops.json
keep $L
python3 - "$root/$L" <<'PY'
import json, sys
p = sys.argv[1]
d = json.load(open(p))
d["lengths"][0]["why"] = ""
json.dump(d, open(p, "w"), indent=2)
PY
t 10 "$X wcet"
put_back $L
sed '0,/"bound": /s//"bound": 100000, "bound": /' "$kept/${L//\//%}" >"$root/$L"
t 9 "$X wcet"
python3 - "$root/$L" <<'PY'
import json, sys
p = sys.argv[1]
d = json.load(open(p))
d["loops"][0]["jobs"] = ["decidng"]
json.dump(d, open(p, "w"), indent=2)
PY
t 23 "$X wcet"
put_back $L
# Item 21: a README that is a FIFO: refused at once, not waited on.
keep README.md
rm "$root/README.md" && mkfifo "$root/README.md"
t 21 "$X wcet"
rm "$root/README.md" && put_back README.md
[ "${SLOW:-0}" = 1 ] || exit 0
# Item 1: a bound whose sums overflow (status 1 naming it, never 101); 8: a general entry of
# critical_section::with before its `within` one: the within one still bounds record::flush's
# loop, and the general one is reported unused (status 1).
python3 - "$root/$L" <<'PY'
import json, sys
p = sys.argv[1]
d = json.load(open(p))
for l in d["loops"]:
    if l["function"].endswith("Search<_,_>::step_until"):
        l["bound"] = 10000
json.dump(d, open(p, "w"), indent=2)
PY
t 1 "$X wcet"
python3 - "$root/$L" "$kept/${L//\//%}" <<'PY'
import json, sys
d = json.load(open(sys.argv[2]))
cs = [i for i, l in enumerate(d["loops"]) if l["function"] == "critical_section::with"]
d["loops"].insert(cs[0], {"function": "critical_section::with", "bound": 0, "why": "general"})
json.dump(d, open(sys.argv[1], "w"), indent=2)
PY
t 8 "$X wcet 2>&1 | grep -m1 'critical_section::with (jobs \[\]) matches no loop' >&2"
put_back $L
# Item 3: a size snapshot with a huge figure: one line, status 1.
S=firmware/size.json
keep $S
sed '0,/"flash": [0-9]*/s//"flash": 18446744073709551615/' "$kept/${S//\//%}" >"$root/$S"
t 3 "$X size"
put_back $S
# Item 5: two scenarios of one file name in two folders: each its own image and outputs.
mkdir -p "$work/a" "$work/b"
cp "$root/scenarios/sonar-6.json" "$work/a/door.json"
sed 's/"door_m": [0-9.]*/"door_m": 1.0/' "$root/scenarios/quiet.json" >"$work/b/door.json"
t 5 "$X hil --json $work/a/door.json $work/b/door.json | grep -o '\"reached_door\":[a-z]*' | tr '\n' ' ' >&2"
# Item 6: a hang 1 ns after boot ends promptly (status 1: the watchdog was not yet started).
fault early.json '"fault": {"kind": "hang", "at_s": 0.000000001}, "expect": {"watchdog_resets": 1}'
t 6 "$X hil $work/early.json"
# Item 14: a hang after the goal: "the fault never struck" (status 1).
fault late.json '"fault": {"kind": "hang", "at_s": 500}, "expect": {"reached_door": true}'
t 14 "$X hil $work/late.json 2>&1 | grep -m1 'never struck' >&2; exit \${PIPESTATUS[0]}"
# Item 16: a run cut at max_s 1 s: judged as psmpa-sim's (not at the door), status 0.
sed 's/"name": "quiet",/"name": "quiet", "max_s": 1,/' "$quiet" >"$work/cut.json"
t 16 "$X hil $work/cut.json"
# Item 17: a crafted name is printed escaped.
printf '{"name": "x\\u001b[32m OK\\nall 26 runs passed", "max_s": 1, "interferences": []}' >"$work/crafted.json"
t 17 "$X hil $work/crafted.json 2>&1 | grep -c \$'\\x1b' >&2"
# Item 26: no image left behind by a failed run.
t 26 "ls $root/target/hil/*.bin 2>/dev/null | wc -l >&2"
