#!/usr/bin/env bash
# A newcomer's first hour (issue 30), replayed: the commands a game programmer tried with the
# README and --help only, each with its output. Run it with the dynatex to look at:
#
#   benchmarks/newcomer_transcript.sh PYTHON WORK_DIR [REPO]
#
# PYTHON runs `-m dynatex`; WORK_DIR gets textures.h5 (grass: tiles, sea: lds + mixture, rust:
# quilt, steam: lds + turnpoints, analysed from ../shared/data/clips when absent) and the outputs;
# REPO (default: this checkout) holds examples/game_loop.py. PYGAMELESS, when set, is a Python
# without pygame to run the example with, as after the README's base install.
set -uo pipefail
PY=$1
WORK=$2
REPO=${3:-$(cd "$(dirname "$0")/.." && pwd)}
CLIPS=${CLIPS:-$REPO/../shared/data/clips}
mkdir -p "$WORK" && cd "$WORK" || exit 1
run() { echo "\$ $*"; "$@" 2>&1 | sed 's/^/    /'; echo; }
dx() { run "$PY" -m dynatex "$@"; }

if [ ! -f textures.h5 ]; then
    "$PY" -m dynatex analyze "$CLIPS/grass_straw_wind_dyntex.avi" -o textures.h5 --name grass --methods tiles -q
    "$PY" -m dynatex analyze "$CLIPS/water_sea_waves_dyntex.avi" -o textures.h5 --name sea --methods lds,mixture --n 20 -q
    "$PY" -m dynatex analyze "$CLIPS/timevarying_rusting_steel.gif" -o textures.h5 --name rust --methods quilt -q
    "$PY" -m dynatex analyze "$CLIPS/steam_vapour_pot_128px.avi" -o textures.h5 --name steam --methods lds,turnpoints -q
fi

echo "## 1. the public surface"
run "$PY" -c "import dynatex; print([n for n in dir(dynatex) if not n.startswith('__')])"
run "$PY" -c "import sys, dynatex
print('imported by import dynatex:', sorted(m for m in sys.modules if m.split('.')[0] in ('cv2', 'scipy', 'dask') or m.startswith('dynatex.analyzer')))"
run "$PY" -c "import dynatex; help(dynatex.open_player)" 
run "$PY" -c "import dynatex, json; d = dynatex.describe('textures.h5'); print(json.dumps(d['textures'], indent=1)); print(d['modes']['lds']['controls']['speed'])"
dx info textures.h5

echo "## 2. defaults that guess right"
dx play textures.h5 --texture grass -o grass.mp4 --frames 20
dx play textures.h5 --texture rust --mode quilt -o rust_q.mp4 --frames 5

echo "## 3. mistakes caught"
run "$PY" -c "
import dynatex
from dynatex.player import open_player  # dynatex.open_player where it exists, the same function
p = open_player('textures.h5', 'sea', mode='lds', backend='numpy')
for name in ('sped', 'draws'):
    try:
        setattr(p, name, 2); print(f'p.{name} = 2 accepted')
    except AttributeError as e:
        print(type(e).__name__ + ':', e)
t = open_player('textures.h5', 'steam', mode='turnpoints', backend='numpy')
try:
    t.intensity = 2; print('turnpoints p.intensity = 2 accepted')
except AttributeError as e:
    print(type(e).__name__ + ':', e)
try:
    open_player('textures.h5', 'sea', mode='lds', size=(1080, 1920))
except TypeError as e:
    print(type(e).__name__ + ':', e)
g = open_player('textures.h5', 'grass', mode='tiles', size=(1920, 1080), backend='numpy')
print('tiles size=(1920, 1080) gives frames of shape', g.shape)
"
dx play textures.h5 --texture sea --mode mixture --speed 0.5 -o x.mp4

echo "## 4. the example after the README's install"
if [ -n "${PYGAMELESS:-}" ]; then
    run env SDL_VIDEODRIVER=dummy "$PYGAMELESS" "$REPO/examples/game_loop.py" textures.h5 --texture sea --frames 5
fi
run env SDL_VIDEODRIVER=dummy SDL_AUDIODRIVER=dummy "$PY" "$REPO/examples/game_loop.py" textures.h5 --texture sea --mode lds --frames 150 --autopilot --fps 60

echo "## 5. export of 80 frames of the 352x288 grass"
rm -rf fx
dx export textures.h5 --texture grass --mode tiles --frames 80 -o fx/
run "$PY" -c "
import json, glob, cv2, numpy as np
d = json.load(open('fx/grass.json'))
cells = d['cols'] * d['rows']
print({k: d[k] for k in ('cols', 'rows', 'frames', 'tile_width', 'tile_height', 'atlas_width', 'atlas_height')})
print('empty cells', cells - d['frames'], 'of', cells, f'= {(cells - d[\"frames\"]) / cells:.1%}',
      '| frame aspect', round(352 / 288, 4), 'cell aspect', round(d['tile_width'] / d['tile_height'], 4))
print('packing in the sidecar:', d.get('packing'))
atlas = cv2.imread(sorted(glob.glob('fx/grass_*x*.png'))[0])
print('atlas', atlas.shape, 'black share of its pixels', round(float((atlas.max(axis=2) == 0).mean()), 4))
"

echo "## 6. slips"
run bash -c "'$PY' -m dynatex play textures.h5 --texture rust --mode evolve --help | grep -A3 -- '--no-interpolate'"
rm -rf rust_frames && mkdir rust_frames
dx play textures.h5 --texture rust --mode evolve -o rust_frames/
run "$PY" -c "
import glob, cv2, numpy as np
f = [cv2.imread(p) for p in sorted(glob.glob('rust_frames/*.png'))]
still = 0
while still + 1 < len(f) and np.array_equal(f[-1 - still - 1], f[-1]):
    still += 1
print(len(f), 'frames written;', still, 'of them repeat the last one')
"
dx bench textures.h5 --texture grass --mode tiles --size 640x360 --frames 20
