import sys

from ecodrive_bench.bench.regression.check import main

sys.exit(main())
