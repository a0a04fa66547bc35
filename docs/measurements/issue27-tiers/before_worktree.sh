# Sourced by the before/after scripts here (alternate_commits.sh, twelfth-stop/snap_before_after.sh), from the
# repository root after `make install`, with `before` set to a commit: checks that commit out as a git worktree in a
# temporary folder ($root, removed on exit), compiles or loads its numba kernels there once, and sets $here and $py.
# Run its code with: $py $here/run_at.py "$root" SCRIPT [ARGS...]
root=$(mktemp -d)/before
git worktree add -q "$root" "$before"
trap 'git worktree remove --force "$root"' EXIT
here=docs/measurements/issue27-tiers
py=.venv/bin/python
$py $here/run_at.py "$root" --warmup
