"""Python-side helpers of the probeless package: the nodes' main() error policy, to_dict."""

import sys

import numpy as np

from . import _probeless


def run_main(name, body):
    """Runs ``body()`` with the C++ nodes' error policy (node/main.h) and exits with its result.

    ``body`` returns the exit code (None = 0). Bad input (NodeError, MessageError, ValueError,
    TypeError) prints ``[error] [name] message`` and exits 2; any other exception prints the
    same line and exits 1, as a C++ node run through RunMain does.
    """
    try:
        code = body()
    except (_probeless.NodeError, _probeless.MessageError, ValueError, TypeError) as error:
        print(f"[error] [{name}] {error}", file=sys.stderr, flush=True)
        code = 2
    except Exception as error:  # noqa: BLE001  (the policy: one line, exit 1)
        print(f"[error] [{name}] {error}", file=sys.stderr, flush=True)
        code = 1
    sys.stdout.flush()
    sys.exit(0 if code is None else code)


def to_dict(message):
    """The fields of a ``probeless.msgs`` object as plain Python values (arrays copied)."""
    out = {}
    for field in type(message).fields:
        value = getattr(message, field)
        if hasattr(type(value), "fields"):
            value = to_dict(value)
        elif isinstance(value, np.ndarray):
            value = value.tolist()
        out[field] = value
    return out
