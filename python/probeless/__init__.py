"""probeless from Python: the bus, the node runtime, messages, logs and estimators.

Everything is the C++ code of the project, bound with pybind11 (docs/python.md):

- ``Node``: the C++ node runtime (ROS 2 arguments, params, remaps, namespaces, logging,
  SIGINT/SIGTERM shutdown, acknowledgements for lock-step replay).
- ``Publisher`` / ``Subscriber`` on the shared-memory bus. A received ``Sample`` and a ``Loan``
  are the slot itself: ``sample.msg.pixels`` is a numpy view of the publisher's shared memory,
  valid until ``release()`` (or the end of a ``with`` block); ``loan.msg.pixels`` is written in
  place, then ``loan.publish()``.
- ``msgs``: every message type with its fields (arrays as numpy views).
- ``log.McapReader``: MCAP logs decoded into ``msgs`` objects.
- ``face_light.FaceLightEstimator``, ``light.ScenePipeline``: the nodes' estimators on arrays.
"""

from ._probeless import (  # noqa: F401  (the package's public names)
    BusError,
    FaceLightError,
    LightError,
    Loan,
    LogError,
    MessageError,
    MessageInfo,
    Node,
    NodeError,
    ParamInfo,
    Publisher,
    Rate,
    Sample,
    Subscriber,
    clean_dead_segments,
    current_domain,
    face_light,
    install_signal_handlers,
    light,
    list_topics,
    log,
    msgs,
    ok,
    request_shutdown,
    validate_topic_name,
    wait_for_shutdown,
)
from ._node import run_main, to_dict  # noqa: F401

__all__ = [
    "BusError", "FaceLightError", "LightError", "Loan", "LogError", "MessageError",
    "MessageInfo", "Node", "NodeError", "ParamInfo", "Publisher", "Rate", "Sample",
    "Subscriber", "clean_dead_segments", "current_domain", "face_light",
    "install_signal_handlers", "light", "list_topics", "log", "msgs", "ok",
    "request_shutdown", "run_main", "to_dict", "validate_topic_name", "wait_for_shutdown",
]
