import sys

from rangekit.cli import main

try:
    code = main()
except KeyboardInterrupt:   # after the command's own handling: still exit 130, never a death by signal
    code = 130
sys.exit(code)
