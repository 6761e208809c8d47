#!/usr/bin/env bash
# Issue 17's hostile cases through the release binary, one row each: wall seconds, max RSS
# (MB), exit code and the first line of the message (stderr, else stdout). The figures of
# the table of issue 17's cases in README.md's "Constraint files" section come from this
# script; the regression tests that pin the answers are named in docs/fuzzing.md ("Issue 17
# cases").
#
# Not here: assertions (the tests in tests/hostile.rs, tests/cli_*.rs, tests/generate.rs,
# tests/simulate.rs, tests/fuzz.rs and constraints/invalid/ hold them); any timer in the
# tests (this script only measures).
#
# Usage, from the crate root after `cargo build --release`:
#     tests/fuzz/issue17.sh            # every case, about a minute on 2 cores
# Needs GNU time (/usr/bin/time) and coreutils' timeout and truncate. Each run is killed after
# 120 s (shown as exit 124) and limited to 4 GB of address space.
set -u
BIN=${BIN:-target/release/lagrange}
CORPUS=tests/fuzz/corpus
TMP=$(mktemp -d "${TMPDIR:-/tmp}/lagrange-issue17.XXXXXX")
trap 'rm -rf "$TMP"' EXIT

# measure LABEL ARGS…: one row "LABEL | wall s | CPU s | RSS MB | exit | first line" (CPU is
# user + system time, less sensitive than the wall clock to a loaded machine).
measure() {
    local label=$1
    shift
    (
        ulimit -v 4000000
        /usr/bin/time -v -o "$TMP/time" timeout 120 "$BIN" "$@" >"$TMP/out" 2>"$TMP/err" </dev/null
    )
    local code wall cpu rss line
    code=$(sed -n 's/^\tExit status: //p' "$TMP/time")
    # "Elapsed (wall clock) time (h:mm:ss or m:ss): 0:01.23"
    wall=$(sed -n 's/^\tElapsed (wall clock) time.*: //p' "$TMP/time" | awk -F: '{ s = 0; for (i = 1; i <= NF; i++) s = s * 60 + $i; printf "%.2f", s }')
    cpu=$(awk -F': ' '/User time|System time/ { s += $2 } END { printf "%.2f", s }' "$TMP/time")
    rss=$(sed -n 's/^\tMaximum resident set size (kbytes): //p' "$TMP/time" | awk '{ printf "%.0f", $1 / 1024 }')
    # The first line that is not a note on stderr, else the status line or first line of stdout.
    line=$(grep -m1 -v -e '^\s*$' -e '^note:' "$TMP/err")
    [ -z "$line" ] && line=$(grep -m1 -e '(status: ' -e '"status":' "$TMP/out")
    [ -z "$line" ] && line=$(grep -m1 -v '^\s*$' "$TMP/out")
    [ "${code:-}" = "" ] && code=$(grep -o 'Command terminated by signal [0-9]*' "$TMP/time" || echo '?')
    printf '%s | %s | %s | %s | %s | %s\n' "$label" "$wall" "$cpu" "$rss" "$code" "$(printf '%s' "$line" | tr -d '\r' | cut -c1-110)"
}

# bead FILE EXPR: the bead of tests/hostile.rs with one constraint.
bead() {
    printf 'title = "hostile"\ndimension = 2\n[parameters]\nl = 1.0\nm = 1.0\n[[bodies]]\nname = "bead"\nposition = "r"\nvelocity = "v"\nacceleration = "a"\nmass = "m"\nforce = "F"\n[[constraints]]\nname = "wire"\nexpr = '"'"'%s'"'"'\n' "$2" >"$1"
}
body() { printf '[[bodies]]\nname = "%s"\nposition = "r%s"\nvelocity = "v%s"\nacceleration = "a%s"\nmass = "m"\nforce = "F%s"\n' "$1" "$2" "$2" "$2" "$2"; }

# ---- files made here (the others are the corpus's) ----
scene='[scene]\ninitial = { r = [1.0, 0.0], v = [0.0, 1.0] }\n'
bead "$TMP/sqrt_nan.toml" 'sqrt(r.y) - 1 = 0'
printf '[[expect]]\nforce = { bead = "[1, 2]" }\n' >>"$TMP/sqrt_nan.toml"
bead "$TMP/ln_nan.toml" 'ln(r.x) = 0'
printf '[[expect]]\nforce = { bead = "[1, 2]" }\n' >>"$TMP/ln_nan.toml"
{
    printf 'title = "undefined nearby"\ndimension = 2\n[parameters]\nm = 1.0\n'
    body b0 0; body b1 1
    printf '[[constraints]]\nname = "c0"\nexpr = "r1.x = 0"\n[[constraints]]\nname = "c1"\nexpr = "r0.y = 0"\n'
    printf '[[constraints]]\nname = "c2"\nexpr = "asin(r0.x) = 0"\n[[expect]]\nforce = { b0 = "[1, 2]" }\n'
} >"$TMP/three.toml"
sed 's/^dt = .*/dt = 1e-320/' constraints/pendulum.toml >"$TMP/tiny_dt.toml"
truncate -s 3G "$TMP/big3g.toml"
e=r.x; for _ in 1 2 3 4 5 6 7 8; do e="atan2($e, r.y)"; done
bead "$TMP/atan2_8.toml" "$e = 0"
{
    printf 'title = "aliases"\ndimension = 2\n[parameters]\nl = 1.0\nm = 1.0\n[definitions]\nd0 = "r.x"\n'
    for i in $(seq 1 3000); do printf 'd%d = "d%d"\n' "$i" $((i - 1)); done
    body bead ""
    printf '[[constraints]]\nname = "wire"\nexpr = "dot(r, r) = l^2"\n'
} >"$TMP/aliases3000.toml"
{
    printf 'title = "all pairs"\ndimension = 2\n[parameters]\nm = 1.0\n'
    for i in $(seq 1 80); do body "b$i" "$i"; done
    for i in $(seq 1 80); do for j in $(seq $((i + 1)) 80); do
        printf '[[constraints]]\nname = "d%d_%d"\nexpr = "norm(r%d - r%d) = 1"\n' "$i" "$j" "$i" "$j"
    done; done
} >"$TMP/pairs80.toml"
for i in $(seq 1 80); do
    awk -v i="$i" 'BEGIN { a = i * 0.7; r = 1 + i * 0.1; printf "r%d = [%.17g, %.17g]\nv%d = [0.0, 0.0]\nF%d = [0.0, -9.81]\n", i, r * cos(a), r * sin(a), i, i }'
done >"$TMP/pairs80_state.toml"
printf 'r = [0.1, 0.2, 0.3]\nv = [0.0, 0.0, 0.0]\nF = [0.0, 0.0, 0.0]\n' >"$TMP/poly3d_state.toml"
cat >"$TMP/two_scales.toml" <<'EOF'
title = "Two pendulums far apart in size"
dimension = 2
[parameters]
L = 1e200
l = 1.0
m = 1.0
[[bodies]]
name = "big"
position = "R"
velocity = "V"
acceleration = "A"
mass = "m"
force = "G"
[[bodies]]
name = "small"
position = "r"
velocity = "v"
acceleration = "a"
mass = "m"
force = "F"
[[constraints]]
name = "big_rod"
expr = "dot(R,R) = L^2"
[[constraints]]
name = "small_rod"
expr = "dot(r,r) = l^2"
[scene]
initial = { R = [1e200, 0.0], V = [0.0, 1e199], r = [1.0, 0.0], v = [0.0, 1.0] }
forces = { G = "[0, 0]", F = "[0, 0]" }
dt = 1e-3
duration = 1.0
EOF
sed 's/^restitution = .*/restitution = 1.0/' constraints/hard/bounce.toml >"$TMP/bounce_e1.toml"
bead "$TMP/huge_scale.toml" 'r.x*1e400 = 1'
printf "$scene" >>"$TMP/huge_scale.toml"
sed 's/^mass = "m"/mass = 5e-324/' "$TMP/huge_scale.toml" | sed 's/r.x\*1e400 = 1/dot(r, r) = l^2/' >"$TMP/subnormal.toml"
for c in 'exp(1000)*r.x = 1' 'r.x/0 = 1' 'ln(0)*r.x = 1'; do
    f="$TMP/failed_$(printf '%s' "$c" | tr -c 'a-z0-9' '_').toml"
    bead "$f" "$c"; printf "$scene" >>"$f"
done
bead "$TMP/x.toml" 'dot(r, r) = l^2'
printf "$scene" >>"$TMP/x.toml"
ln -s "$TMP/x.toml" "$TMP/link.csv"
name='wire\u001b[2K\r\nok     fake.toml:1:1: all fine'
bead "$TMP/ansi.toml" 'dot(r, r) = l^2'
sed -i "s/^name = \"wire\"/name = \"${name//\\/\\\\}\"/" "$TMP/ansi.toml"
printf '[[expect]]\nlambda = { "%s" = "42" }\n' "$name" >>"$TMP/ansi.toml"
bead "$TMP/title.toml" 'dot(r, r) = l^2'
sed -i 's/^title = "hostile"/title = "Bead\\n\\n<script>alert(1)<\/script>\\n# Not a heading"/' "$TMP/title.toml"
sed 's/^name = "wire"/name = "=a,b\\nc"/' "$TMP/x.toml" >"$TMP/csvname.toml"
printf '{"r": [1, 0], "r": [0, 1], "v": [0, 1]}\n' >"$TMP/dup.json"
"$BIN" --version >/dev/null 2>&1 || true

echo "case | wall s | CPU s | max RSS MB | exit | first line"
measure "check acos NaN (SVD panic)" check "$CORPUS/check_acos_nan.toml"
measure "check sqrt(r.y)-1 NaN" check "$TMP/sqrt_nan.toml"
measure "check ln(r.x) NaN" check "$TMP/ln_nan.toml"
measure "check 3 constraints (hang)" check "$TMP/three.toml"
measure "bench --states 1e8" bench constraints/pendulum.toml --states 100000000
measure "simulate --duration inf" simulate constraints/pendulum.toml --duration inf
measure "simulate --duration 1e300" simulate constraints/pendulum.toml --duration 1e300
measure "simulate scene dt = 1e-320" simulate "$TMP/tiny_dt.toml"
measure "simulate --duration nan" simulate constraints/pendulum.toml --duration nan
measure "simulate --dt 1e300" simulate constraints/pendulum.toml --dt 1e300
measure "bench --duration 1e300" bench constraints/pendulum.toml --duration 1e300
measure "bench --dt 1e-300" bench constraints/pendulum.toml --dt 1e-300
measure "derive /dev/zero" derive /dev/zero
measure "derive 3 GB sparse file" derive "$TMP/big3g.toml"
measure "derive atan2 depth 6" derive "$CORPUS/atan2_depth6.toml"
measure "derive atan2 depth 8" derive "$TMP/atan2_8.toml"
measure "derive tower 64" derive "$CORPUS/tower64.toml"
measure "derive definitions12" derive "$CORPUS/definitions12.toml"
measure "derive 3000 aliases" derive "$TMP/aliases3000.toml"
measure "derive 3^1000000" derive "$CORPUS/pow3_1000000.toml"
measure "derive (2/3)^100000" derive "$CORPUS/pow23_100000.toml"
measure "derive negpow" derive "$CORPUS/negpow.toml"
measure "generate --specialize negpow" generate --specialize "$CORPUS/negpow.toml"
measure "derive binomials2000" derive "$CORPUS/binomials2000.toml"
measure "derive sqrt60" derive "$CORPUS/sqrt60.toml"
measure "derive product300" derive "$CORPUS/product300.toml"
measure "solve 80 bodies all pairs" solve "$TMP/pairs80.toml" --at "$TMP/pairs80_state.toml"
measure "derive dots2000" derive "$CORPUS/dots2000.toml"
measure "generate dots2000" generate "$CORPUS/dots2000.toml"
measure "generate --specialize dots2000" generate --specialize "$CORPUS/dots2000.toml"
measure "derive poly3d" derive "$CORPUS/poly3d.toml"
measure "solve poly3d" solve "$CORPUS/poly3d.toml" --at "$TMP/poly3d_state.toml"
measure "solve two scales 1e200 + 1" solve "$TMP/two_scales.toml" --format json
measure "simulate two scales" simulate "$TMP/two_scales.toml"
measure "solve bead --set l=1e200" solve constraints/bead_on_wire.toml --set l=1e200
measure "simulate bounce e=1 baumgarte" simulate "$TMP/bounce_e1.toml" --stabilize baumgarte
measure "check 1e200 expectation" check "$CORPUS/check_huge.toml"
measure "generate hard/huge.toml" generate constraints/hard/huge.toml
measure "solve r.x*1e400 = 1" solve "$TMP/huge_scale.toml"
measure "generate r.x*1e400 = 1" generate "$TMP/huge_scale.toml"
measure "solve subnormal mass" solve "$TMP/subnormal.toml"
for f in "$TMP"/failed_*.toml; do measure "solve $(sed -n "s/^expr = '\(.*\)'/\1/p" "$f")" solve "$f"; done
measure "generate x.toml -o x.toml" generate "$TMP/x.toml" -o "$TMP/x.toml"
measure "simulate --csv x.toml" simulate "$TMP/x.toml" --steps 10 --csv "$TMP/x.toml"
measure "simulate --plot x.toml" simulate "$TMP/x.toml" --steps 10 --plot "$TMP/x.toml"
measure "simulate --csv symlink to x.toml" simulate "$TMP/x.toml" --steps 10 --csv "$TMP/link.csv"
measure "simulate --csv /dev/full" simulate "$TMP/x.toml" --steps 10 --csv /dev/full
measure "check ANSI name" check "$TMP/ansi.toml"
measure "derive newline title (markdown)" derive "$TMP/title.toml" --format markdown
measure "derive newline title (latex)" derive "$TMP/title.toml" --format latex
measure "simulate CSV name =a,b\\nc" simulate "$TMP/csvname.toml" --steps 2 --csv "$TMP/names.csv"
echo "  (CSV header: $(head -c 80 "$TMP/names.csv" | tr '\n' '~'))"
measure "solve --at duplicate JSON key" solve "$TMP/x.toml" --at "$TMP/dup.json"
# The chain file comes from the example (`cargo build --release --example chain`).
CHAIN=${CHAIN:-target/release/examples/chain}
[ -x "$CHAIN" ] && "$CHAIN" 2000 >"$TMP/chain2000.toml" 2>/dev/null
[ -s "$TMP/chain2000.toml" ] && measure "generate chain 2000" generate "$TMP/chain2000.toml" -o "$TMP/chain2000.rs"
