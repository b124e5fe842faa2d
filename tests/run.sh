#!/usr/bin/env bash
# The one test command: installs missing Debian packages, then fmt, clippy, all tests and smoke
# runs of the binaries. Used as is by CI (.ci/run) with CI=true.
set -euo pipefail
cd "$(dirname "$0")/.."

step() { printf '\n==> %s\n' "$*"; }

# --- system packages (lavapipe for GPU tests, Xvfb + X libraries for the viewer smoke run) ---
packages=(mesa-vulkan-drivers libvulkan1 xvfb libx11-6 libx11-xcb1 libxcb1 libxcursor1 libxi6
          libxkbcommon-x11-0 xdotool pkg-config fonts-dejavu-core python3 python3-venv)
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  step "installing Debian packages: ${missing[*]}"
  sudo=""
  [ "$(id -u)" -ne 0 ] && sudo="sudo"
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

# --- Rust components ---
if ! cargo fmt --version >/dev/null 2>&1 || ! cargo clippy --version >/dev/null 2>&1; then
  step "installing rustfmt and clippy"
  rustup component add rustfmt clippy
fi

step "cargo fmt --check"
cargo fmt --all -- --check

step "cargo clippy (all targets, warnings are errors)"
cargo clippy --workspace --all-targets --locked -- -D warnings

step "cargo doc (rustdoc lints, warnings are errors)"
RUSTDOCFLAGS="-D warnings" cargo doc --workspace --no-deps --locked --quiet

# The viewer test (tests/tests/e2e/viewer_xvfb.rs) drives the flyover binary: build it first.
step "cargo build --bins"
cargo build --workspace --bins --locked

step "cargo test"
rm -f target/test-skips.txt
FLYOVER_BIN="$PWD/target/debug/flyover" cargo test --workspace --locked 2>&1 | tee target/test-output.log
# Fail loudly if the runner executed nothing (e.g. everything filtered out): count the tests
# that ran (doc-test summaries say "ok" with 0 passed, so a grep for "ok" proves nothing).
ran=$(grep -oE "test result: ok\. [0-9]+ passed" target/test-output.log | awk '{s+=$4} END {print s+0}')
if [ "$ran" -eq 0 ]; then
  echo "cargo test ran no test" >&2; exit 1
fi

# --- smoke runs: the binaries in the dev profile (deps already built by the tests) ---

step "smoke: worldgen generate / check / import-dem"
smoke=target/smoke
rm -rf "$smoke" && mkdir -p "$smoke"
./target/debug/worldgen generate --seed 11 --size 1024 --out "$smoke/gen" --quiet
./target/debug/worldgen check "$smoke/gen" >/dev/null
./target/debug/worldgen check maps/tiny >/dev/null
if ./target/debug/worldgen check "$smoke/does-not-exist" 2>/dev/null; then
  echo "worldgen check accepted a missing map" >&2; exit 1
fi
./target/debug/worldgen import-dem tests/data/dem/N57E011.hgt --out "$smoke/n57" --quiet >/dev/null
./target/debug/worldgen check "$smoke/n57" >/dev/null

step "distributed bake: Dask on a local cluster of two workers equals the local bake"
# Dask in a virtual environment of its own under target/ (kept between runs).
pyenv=target/pyenv
if ! "$pyenv/bin/python" -c "import dask.distributed" 2>/dev/null; then
  /usr/bin/python3 -m venv "$pyenv"
  "$pyenv/bin/pip" install -q "dask[distributed]==2026.8.0"
fi
cp -r "$smoke/gen" "$smoke/bake-local" && cp -r "$smoke/gen" "$smoke/bake-dask"
./target/debug/worldgen bake "$smoke/bake-local" --page-side 64 --quiet >/dev/null
"$pyenv/bin/python" apps/dask/bake.py "$smoke/bake-dask" --worldgen ./target/debug/worldgen \
  --local-workers 2 --shares 6 --page-side 64 > "$smoke/bake-dask.log"
test "$(grep -oE "on worker tcp://[0-9.]+:[0-9]+" "$smoke/bake-dask.log" | sort -u | wc -l)" -eq 2
# Every file under pages/ (the layers, the decal list, the record of sources and the derived
# pyramids, decal tiles and surface error grids; no partial file left over).
test "$(find "$smoke/bake-local/pages" -type f | wc -l)" -ge 8
test -s "$smoke/bake-local/pages/derived/surface_error.levels"
diff -r "$smoke/bake-local/pages" "$smoke/bake-dask/pages"
./target/debug/worldgen check "$smoke/bake-dask" > "$smoke/check.log"
grep -q "page files: .* every one matches its checksum and this map" "$smoke/check.log"
grep -q "derived data: .* every part baked for this map and this engine" "$smoke/check.log"
# Derived data missing or damaged: check fails naming the part, or the file and the page.
cp -r "$smoke/bake-local" "$smoke/bake-stale"
rm "$smoke/bake-stale/pages/derived/heights_stride_2.pages"
if ./target/debug/worldgen check "$smoke/bake-stale" 2> "$smoke/stale.log" >/dev/null; then
  echo "worldgen check accepted a map missing derived data" >&2; exit 1
fi
grep -q "derived data missing, damaged or baked for another map or engine: coarse height levels" "$smoke/stale.log"
cp -r "$smoke/bake-local" "$smoke/bake-damaged"
/usr/bin/python3 -c 'import sys; p = sys.argv[1]; b = bytearray(open(p, "rb").read()); b[100] ^= 1; open(p, "wb").write(b)' \
  "$smoke/bake-damaged/pages/derived/slope_g.0.pages"
if ./target/debug/worldgen check "$smoke/bake-damaged" 2> "$smoke/damaged.log" >/dev/null; then
  echo "worldgen check accepted a damaged derived page" >&2; exit 1
fi
grep -q "slope_g.0.pages: page (0, 0) does not match its checksum" "$smoke/damaged.log"
# A flipped byte in the first page: check fails naming the file and the page.
/usr/bin/python3 -c 'import sys; p = sys.argv[1]; b = bytearray(open(p, "rb").read()); b[164] ^= 1; open(p, "wb").write(b)' \
  "$smoke/bake-dask/pages/heights.exr.pages"
if ./target/debug/worldgen check "$smoke/bake-dask" 2> "$smoke/bad-page.log" >/dev/null; then
  echo "worldgen check accepted a damaged page" >&2; exit 1
fi
grep -q "heights.exr.pages: page (0, 0) does not match its checksum" "$smoke/bad-page.log"

step "smoke: worldgen pm (progressive mesh of a test model)"
./target/debug/worldgen pm tests/data/meshes/spot.obj --out "$smoke/spot.pm" --quiet >/dev/null
test -s "$smoke/spot.pm"
if ./target/debug/worldgen pm maps/tiny/map.toml --out "$smoke/bad.pm" 2>/dev/null; then
  echo "worldgen pm accepted a file that is not a mesh" >&2; exit 1
fi
./target/debug/lod-error "$smoke/spot.pm" --plot "$smoke/lod_error.png" > "$smoke/lod_error.md"
grep -q "stored bound" "$smoke/lod_error.md"
test -s "$smoke/lod_error.png"

step "smoke: worldgen building (a procedural house as a progressive mesh)"
./target/debug/worldgen building --roof hip --out "$smoke/house.obj" --quiet
./target/debug/worldgen pm "$smoke/house.obj" --out "$smoke/house.pm" --quiet >/dev/null
test -s "$smoke/house.pm"
if ./target/debug/worldgen building --roof dome --out "$smoke/bad.obj" 2>/dev/null; then
  echo "worldgen building accepted an unknown roof" >&2; exit 1
fi

step "smoke: nodebench --quick on the tiny map"
./target/debug/nodebench --quick --map maps/tiny --json "$smoke/nodebench.json" --plot "$smoke/speed_vs_error.png" --pm-plot "$smoke/pm_error.png" --doc "$smoke/bench.md" > "$smoke/nodebench.md"
grep -q "^# Benchmarks" "$smoke/bench.md"
test ! -e "$smoke/bench.partial.md"
grep -q '"section": "selection"' "$smoke/nodebench.json"
grep -q '"machine"' "$smoke/nodebench.json"
grep -q '"section": "gpu"' "$smoke/nodebench.json"
grep -q '"section": "soak"' "$smoke/nodebench.json"
grep -q '"section": "bookkeeping"' "$smoke/nodebench.json"
test -s "$smoke/speed_vs_error.png"
grep -q '"section": "pm"' "$smoke/nodebench.json"
for pilot in turning climbing reversing; do
  grep -q "hidden-future pilot $pilot" "$smoke/nodebench.json"
done
if ./target/debug/nodebench --only streaming --pilots barrel-roll --map maps/tiny 2>/dev/null; then
  echo "nodebench accepted an unknown pilot" >&2; exit 1
fi
test -s "$smoke/pm_error.png"
if ./target/debug/nodebench --only nonsense --map maps/tiny 2>/dev/null; then
  echo "nodebench accepted an unknown section" >&2; exit 1
fi
# A run that fails late (here: section worlds cannot make its folder) keeps the rows it measured.
if ./target/debug/nodebench --quick --only tiles,worlds --worlds-scratch /dev/null/worlds \
  --map maps/tiny --doc "$smoke/failed.md" >/dev/null 2>&1; then
  echo "nodebench made a world folder under /dev/null" >&2; exit 1
fi
test ! -e "$smoke/failed.md"
grep -q "Incomplete" "$smoke/failed.partial.md"
grep -q "| tiles |" "$smoke/failed.partial.md"

step "smoke: flyover headless, and its fallback when there is no display"
./target/debug/flyover --headless --map maps/tiny --frames 60 --every 30 --size 320x180 \
  --duration-s 2 --out "$smoke/flyover" > "$smoke/flyover.md"
test -s "$smoke/flyover/frame_00000.png" && test -s "$smoke/flyover/frame_00059.png"
grep -q '"frames"' "$smoke/flyover/stats.json"
# Where the resident memory is at the end (Linux): by mapping, and what is accounted for.
grep -q '"not_accounted_for"' "$smoke/flyover/stats.json"
grep -q "not accounted for" "$smoke/flyover.md"
./target/debug/flyover --headless --map maps/tiny --frames 40 --every 0 --size 320x180 \
  --duration-s 2 --gpu-reference --out "$smoke/flyover-reference" > "$smoke/flyover-reference.md"
grep -q "GPU frame pass / one-draw reference" "$smoke/flyover-reference.md"
env -u DISPLAY -u WAYLAND_DISPLAY ./target/debug/flyover --map maps/tiny --frames 3 --size 64x36 \
  --out "$smoke/flyover-nodisplay" 2> "$smoke/flyover-nodisplay.log" >/dev/null
grep -q "no display" "$smoke/flyover-nodisplay.log"
if ./target/debug/flyover --headless --map "$smoke/does-not-exist" --frames 1 2> "$smoke/flyover-err.log"; then
  echo "flyover accepted a missing map" >&2; exit 1
fi
grep -q "does-not-exist" "$smoke/flyover-err.log"
for bad in "--tau=0" "--fps=0" "--duration-s=-5"; do
  # shellcheck disable=SC2086
  if ./target/debug/flyover --headless --map maps/tiny --frames 1 $bad 2> "$smoke/bad-arg.log" >/dev/null; then
    echo "flyover accepted $bad" >&2; exit 1
  fi
  # Refused for the right reason: the message names the option and the rule.
  if ! grep -q -- "${bad%%=*}" "$smoke/bad-arg.log" \
     || ! grep -q "must be a finite number above 0" "$smoke/bad-arg.log"; then
    echo "flyover refused $bad without saying why:" >&2; cat "$smoke/bad-arg.log" >&2; exit 1
  fi
done

for bad in "--fov-deg=0" "--fov-deg=200" "--fov-deg=nan"; do
  # shellcheck disable=SC2086
  if ./target/debug/flyover --headless --map maps/tiny --frames 1 $bad 2> "$smoke/bad-fov.log" >/dev/null; then
    echo "flyover accepted $bad" >&2; exit 1
  fi
  if ! grep -q "field of view" "$smoke/bad-fov.log"; then
    echo "flyover refused $bad without naming the field of view:" >&2; cat "$smoke/bad-fov.log" >&2; exit 1
  fi
done
if ./target/debug/nodebench --only selection --map maps/tiny --fov-deg 200 2> "$smoke/bad-fov.log" >/dev/null \
   || ! grep -q "field of view" "$smoke/bad-fov.log"; then
  echo "nodebench did not refuse --fov-deg 200 naming the field of view" >&2; exit 1
fi
# A camera file of one's own views at 90 degrees 21:9 (a recorded path's format).
printf 'tvs-camera-path 1\n0 100 100 80 1 1 -0.4\n1 300 200 60 -1 0.5 -0.3\n' > "$smoke/cams.txt"
./target/debug/nodebench --quick --only selection --map maps/tiny --fov-deg 90 --aspect 21:9 \
  --cameras "$smoke/cams.txt" > "$smoke/own-views.md"
grep -q "90° 2.333:1, cameras of" "$smoke/own-views.md"

step "smoke: flyover without any Vulkan driver says what to install (no panic)"
if VK_ICD_FILENAMES=/nonexistent.json VK_DRIVER_FILES=/nonexistent.json \
   ./target/debug/flyover --headless --map maps/tiny --frames 1 --out "$smoke/nodriver" \
   2> "$smoke/nodriver.log" >/dev/null; then
  echo "flyover ran without a Vulkan driver" >&2; exit 1
fi
grep -q "mesa-vulkan-drivers" "$smoke/nodriver.log"
if grep -qiE "panicked|backtrace" "$smoke/nodriver.log"; then
  cat "$smoke/nodriver.log" >&2; echo "flyover panicked without a driver" >&2; exit 1
fi

passed=$ran
failed=$(grep -oE "[0-9]+ failed" target/test-output.log | awk '{s+=$1} END {print s+0}')
step "all checks passed"
if [ -s target/test-skips.txt ]; then
  echo "tests that skipped their checks on this machine (each fails instead in CI):"
  sed 's/^/  - /' target/test-skips.txt
fi
echo "tests: ${passed} passed, ${failed} failed"
