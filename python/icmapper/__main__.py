import sys

from icmapper.cli import main

sys.exit(main())
