import sys

from appsim.cli import main

sys.exit(main())
