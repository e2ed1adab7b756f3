#!/usr/bin/env python3
"""Write a random discoverable forest scenario (YAML): the command of :mod:`rrtq_bringup.forest`.

source scripts/env.sh && python scenarios/envs/make_forest.py --seed 3 --out scenarios/forest_100.yaml
"""

import sys

from rrtq_bringup.forest import main

if __name__ == '__main__':
    sys.exit(main())
