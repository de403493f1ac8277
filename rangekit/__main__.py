from rangekit.cli import main
import sys
sys.exit(main())
