"""``python -m ros_mobile_bridge`` is the ``rmb`` command."""

import sys

from .cli import main

sys.exit(main())
