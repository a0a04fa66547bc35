# The DataLoader example with the fast tier (denoise-fast2) and with the fast tier until this stop (denoise-fast),
# alternating, so that the machine's swings hit both alike. Run from the repository root.
for i in 1 2 3 4; do
    python examples/restore_in_dataloader.py --workers 2 --frames 16 --size 240 320 --tier fast
    python examples/restore_in_dataloader.py --workers 2 --frames 16 --size 240 320 --pretrained denoise-fast
done
