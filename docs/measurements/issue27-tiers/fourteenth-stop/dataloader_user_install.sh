# The DataLoader example in a venv with only what `pip install torch-depth-sr` installs (no test extra, so no SciPy:
# numba's start-up then skips SciPy's BLAS) and in the development venv (`make install`, the test extra with
# scikit-learn and SciPy), alternating. From the repository root:
#   python3 -m venv /tmp/uvenv && /tmp/uvenv/bin/pip install torch==2.13.0 && /tmp/uvenv/bin/pip install -c constraints.txt -e .
#   bash docs/measurements/issue27-tiers/fourteenth-stop/dataloader_user_install.sh
A="--workers 2 --frames 16 --size 240 320 --tier fast"
for i in 1 2 3 4; do
    printf 'user install: '; /tmp/uvenv/bin/python examples/restore_in_dataloader.py $A
    printf 'dev venv:     '; .venv/bin/python examples/restore_in_dataloader.py $A
done
