"""``torch-depth-sr`` with every network in float32, whatever the processor (a ``network_precision`` block): the
float32 side of this stop's comparisons. Arguments as the command line's, e.g.

    OMP_NUM_THREADS=2 python docs/measurements/issue27-tiers/sixteenth-stop/float32_cli.py bench --track gdsr \
        --sets Middlebury Lu --scales 4 --noise 0 5 --methods trained trained-x4-refined --per-scene
"""
import sys

from torch_depth_sr.cli import main
from torch_depth_sr.precision import network_precision

with network_precision("float32"):
    sys.exit(main(sys.argv[1:]))
