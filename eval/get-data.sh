#!/usr/bin/env bash
# Fetch the public real tactile frames for eval/ and lay them out in data/real/.
#
#   eval/get-data.sh                      # sparse, blob-less clones into data/src/
#   eval/get-data.sh --from-mirror DIR    # bare snapshots DIR/<owner>+<name>[/repo]
#
# Options: --python PY (default .venv/bin/python, else python3; needs
# eval/requirements.txt), --frames N (per TacTip shear set, default 200),
# --seed S (default 0). DEXITAC_EVAL_GIT_BASE overrides https://github.com
# (for a local copy, e.g. file:///srv/git).
#
# The data sets carry no licence (gsrobotics is GPL-3.0): everything stays
# under data/ (git-ignored), never commit a frame.
set -euo pipefail
shopt -s inherit_errexit

cd "$(dirname "$0")/.."
mirror="" python="" frames=200 seed=0
while [[ $# -gt 0 ]]; do
  case "$1" in
    --from-mirror) mirror="$2"; shift 2 ;;
    --python) python="$2"; shift 2 ;;
    --frames) frames="$2"; shift 2 ;;
    --seed) seed="$2"; shift 2 ;;
    -h|--help) sed -n '2,15p' "$0"; exit 0 ;;
    *) echo "get-data.sh: unknown argument $1" >&2; exit 2 ;;
  esac
done
if [[ -z "$python" ]]; then
  if [[ -x .venv/bin/python ]]; then python=.venv/bin/python; else python=python3; fi
fi

base=${DEXITAC_EVAL_GIT_BASE:-https://github.com}
SHEAR=dexterousrobot/tactile_data_shear
TIP=dexterousrobot/tactile_image_processing
GELSLIM=siyuandong16/gelsight_heightmap_reconstruction
GSROBOTICS=gelsightinc/gsrobotics
# The commit that added the GelSight Mini marker video (later ones removed it).
GS_MINI_COMMIT=3d1bed69c56d2970d5901a845fdcb3c8da7e9415

# clone REPO PATH... : a depth-1, blob-less clone checking out only PATHs.
clone() {
  local repo=$1; shift
  local dir=data/src/${repo//\//+}
  if [[ -d $dir/.git ]]; then
    echo "get-data.sh: $dir exists, updating its sparse paths" >&2
  else
    mkdir -p data/src
    git clone --quiet --depth 1 --filter=blob:none --no-checkout "$base/$repo" "$dir" || return 1
  fi
  # Exact folders, no cone: only these blobs are fetched.
  printf '/%s/\n' "$@" | git -C "$dir" sparse-checkout set --no-cone --stdin || return 1
  git -C "$dir" checkout --quiet || return 1
  echo "$dir"
}

# clone_at REPO COMMIT PATH : a blob-less clone with PATH checked out at
# COMMIT (not at the tip: the file is gone there), only its blobs fetched.
clone_at() {
  local repo=$1 commit=$2 path=$3
  local dir=data/src/${repo//\//+}
  if [[ ! -d $dir/.git ]]; then
    mkdir -p data/src
    git clone --quiet --filter=blob:none --no-checkout "$base/$repo" "$dir" || return 1
  fi
  printf '/%s\n' "$path" | git -C "$dir" sparse-checkout set --no-cone --stdin || return 1
  git -C "$dir" checkout --quiet "$commit" || return 1
  echo "$dir"
}

# from_mirror REPO : the bare git directory of REPO under $mirror.
from_mirror() {
  local name=${1//\//+}
  for d in "$mirror/$name/repo" "$mirror/$name" "$mirror/$name.git"; do
    if [[ -f $d/HEAD && -d $d/objects ]]; then echo "$d"; return; fi
  done
  echo "get-data.sh: no bare git directory for $1 under $mirror" >&2
  exit 1
}

if [[ -n "$mirror" ]]; then
  shear=$(from_mirror $SHEAR) || exit 1
  tip=$(from_mirror $TIP) || exit 1
  gelslim=$(from_mirror $GELSLIM) || exit 1
  gsrobotics=$(from_mirror $GSROBOTICS) || exit 1
else
  shear=$(clone $SHEAR data/cr_tactip/surface_3d/val_data data/franka_tactip_1/surface_3d/test) || exit 1
  tip=$(clone $TIP readme_images) || exit 1
  gelslim=$(clone $GELSLIM "matlab_version/calibration functions/illumination_calib/Dots1") || exit 1
  gsrobotics=$(clone_at $GSROBOTICS $GS_MINI_COMMIT demos/marker_tracking/data/mini_example.avi) || exit 1
fi

"$python" eval/layout.py --shear "$shear" --tip "$tip" --gelslim "$gelslim" \
  --gsrobotics "$gsrobotics" --out data/real --frames "$frames" --seed "$seed"
# Raw-looking taps (tactip_raw's pins placed as the cr taps put theirs),
# with the raw frame's light and with a light of their own per frame.
"$python" eval/raw_taps.py --data data/real
"$python" eval/raw_taps.py --data data/real --light
