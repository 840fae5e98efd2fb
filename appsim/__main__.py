from appsim.cli import main
import sys
sys.exit(main())
