"""``python -m ros_mobile_bridge`` is the ``rmb`` command. A Ctrl-C while
the command line's modules load is exit 130 with no traceback, as it is
later."""

import sys

try:
    from .cli import main
except KeyboardInterrupt:
    sys.exit(130)

sys.exit(main())
