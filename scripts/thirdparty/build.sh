#!/usr/bin/env bash
# Rebuild the third-party vehicle meshes listed in sources.tsv into OUT_DIR/<category>/<name>.glb
# and check each against the sha256 recorded in the TSV (exit 1 on any mismatch).
#
#   build.sh OUT_DIR [TSV]
#
# TSV is sources.tsv (the validation set) by default; train-sources.tsv lists the disjoint
# training meshes.
#
# Sources come from ${THIRDPARTY_GIT:-https://github.com}/<owner>/<repo> at the listed commit
# (shallow, blob-less fetch: only the files needed are downloaded). For an offline rebuild set
# THIRDPARTY_MIRROR=DIR to read $DIR/<owner>+<repo>/repo as local (bare) git dirs instead.
# Column `how` says what makes each file (see glb.py): obj | gltf | compose | copy, and fbx
# (binary FBX, fbx2glb.py).
set -euo pipefail

out=${1:?usage: build.sh OUT_DIR [TSV]}
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
tsv=${2:-$here/sources.tsv}
glb() { python3 "$here/glb.py" "$@"; }
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
mkdir -p "$out"

# gitdir OWNER/REPO COMMIT -> prints a git dir that has COMMIT
gitdir() {
  local repo=$1 commit=$2 d
  if [[ -n ${THIRDPARTY_MIRROR:-} ]]; then
    d=$THIRDPARTY_MIRROR/${repo/\//+}/repo
    [[ -d $d/.git ]] && d=$d/.git
  else
    d=$work/git/${repo/\//+}
    if [[ ! -d $d ]]; then
      git init -q --bare "$d"
      git --git-dir="$d" remote add origin "${THIRDPARTY_GIT:-https://github.com}/$repo"
    fi
    git --git-dir="$d" cat-file -e "$commit^{commit}" 2>/dev/null ||
      git --git-dir="$d" fetch -q --depth 1 --filter=blob:none origin "$commit" >&2
  fi
  git --git-dir="$d" cat-file -e "$commit^{commit}" || { echo "commit $commit of $repo not found in $d" >&2; return 1; }
  echo "$d"
}

# Columns: 1 category, 2 name, 3 file, 4 repository, 5 path_in_repo, 6 commit, ..., 13 how, 14 sha256.
[[ $(head -1 "$tsv" | cut -f3-6,13,14) == $'file\trepository\tpath_in_repo\tcommit\thow\tsha256' ]] ||
  { echo "unexpected columns in $tsv" >&2; exit 1; }
n=0
while IFS=$'\t' read -r -u 3 file repo path commit how sha; do
  name=$(basename "$file" .glb)
  path=${path%% (*}                          # drop the "(+ companions)" / "(mesh ...)" remark
  gd=$(gitdir "$repo" "$commit")
  src=$work/src/$name/$(dirname "$path")
  mkdir -p "$src"
  f=$src/$(basename "$path")
  git --git-dir="$gd" show "$commit:$path" >"$f"
  if [[ $how == obj || $how == gltf ]]; then  # companions: .mtl, .bin, textures (same commit)
    while IFS= read -r dep; do
      mkdir -p "$(dirname "$src/$dep")"
      git --git-dir="$gd" show "$commit:$(dirname "$path")/$dep" >"$src/$dep"
    done < <(glb deps "$f")
  fi
  dst=$out/$file
  mkdir -p "$(dirname "$dst")"
  case $how in
    obj | gltf) glb "$how" "$f" "$dst" ;;
    compose) glb compose "$f" "$dst" "$here/placements.json" "$name" ;;
    copy) cp "$f" "$dst" ;;
    fbx) python3 "$here/fbx2glb.py" "$f" "$dst" ;;
    *) echo "$name: unknown how '$how'" >&2; exit 1 ;;
  esac
  printf '%s  %s\n' "$sha" "$file" >>"$work/SHA256SUMS"
  n=$((n + 1))
  echo "built $file ($how)"
done 3< <(tail -n +2 "$tsv" | cut -f3-6,13,14)

if ! (cd "$out" && sha256sum --quiet -c "$work/SHA256SUMS"); then
  echo "ERROR: rebuilt meshes differ from the recorded sha256 (see FAILED lines above)" >&2
  exit 1
fi
echo "OK: all $n meshes rebuilt byte-identical to $(basename "$tsv") sha256"
