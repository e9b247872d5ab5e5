"""Pin the numeric path (``vlmrl_cli.core.numeric_pin``) before any test module, plugin or
xdist worker imports torch or numpy: the pinned-returns digests hold on that path only."""

from vlmrl_cli.core.numeric_pin import apply

apply()
