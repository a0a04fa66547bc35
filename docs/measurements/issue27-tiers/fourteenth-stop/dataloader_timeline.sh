# The DataLoader example with the times at which its warm-up ended and each frame arrived (seconds from the start of
# its timed part): examples/restore_in_dataloader.py with two sed substitutions, run three times. From the
# repository root: bash docs/measurements/issue27-tiers/fourteenth-stop/dataloader_timeline.sh
t=$(mktemp --suffix=.py)
sed -e 's/    loader = DataLoader(ds, batch_size=1, num_workers=a.workers)/    t_w = time.perf_counter(); loader = DataLoader(ds, batch_size=1, num_workers=a.workers)/' \
    -e 's/    end = time.perf_counter()/    end = time.perf_counter(); print("warmup", round(t_w - t0, 2), "arrivals", [round(x - t0, 2) for x in arrived])/' \
    examples/restore_in_dataloader.py > "$t"
for i in 1 2 3; do python "$t" --workers 2 --frames 16 --size 240 320 --tier fast; done
rm -f "$t"
