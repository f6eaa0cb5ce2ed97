import sys

from bench.regression.check import main

sys.exit(main())
