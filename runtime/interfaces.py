"""Services and actions as rosidl expands them, registered as message types in the typestore.

rosbags' typestore has messages only. A ROS 2 service ``pkg/srv/Name`` travels as two messages,
``Name_Request`` and ``Name_Response``; an action ``pkg/action/Name`` as three services
(``_action/send_goal``, ``get_result``, ``cancel_goal``) and two topics (``feedback``,
``status``). The rules below are rosidl's (``rosidl_parser.definition.Service`` / ``Action``):

* action: ``Name_Goal``, ``Name_Result``, ``Name_Feedback`` from the three sections;
  ``Name_SendGoal`` = {``unique_identifier_msgs/UUID goal_id``, ``Name_Goal goal``} →
  {``bool accepted``, ``builtin_interfaces/Time stamp``}; ``Name_GetResult`` = {``goal_id``} →
  {``int8 status``, ``Name_Result result``}; ``Name_FeedbackMessage`` = {``goal_id``,
  ``Name_Feedback feedback``}; cancelling is the generic ``action_msgs/srv/CancelGoal``;
* service (for its type hash, REP-2011, Iron and later): ``Name_Event`` = {``service_msgs/
  ServiceEventInfo info``, ``Name_Request[<=1] request``, ``Name_Response[<=1] response``} and
  the service type itself = {``Name_Request request_message``, ``Name_Response
  response_message``, ``Name_Event event_message``}. Registering that as a struct lets rosbags'
  ``hash_rihs01`` compute the service's hash; it reproduces the published hash of
  ``example_interfaces/srv/AddTwoInts`` (tests/runtime/test_interop.py);
* ``char`` is ``uint8`` (rosidl_adapter's .msg → .idl mapping), which the hash depends on.

The definitions are kept verbatim in ``idl/`` (sources in ``idl/README.md``).
"""

from __future__ import annotations

from functools import cache
from importlib import resources
from typing import TYPE_CHECKING, Any

from rosbags.interfaces import Nodetype
from rosbags.typesys import get_types_from_msg

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

IDL_ROOT = "idl"

#: The interfaces kept in ``idl/`` (``pkg/kind/Name``).
NAVIGATE_TO_POSE = "nav2_msgs/action/NavigateToPose"
CANCEL_GOAL = "action_msgs/srv/CancelGoal"
SERVICE_EVENT_INFO = "service_msgs/msg/ServiceEventInfo"
#: Nav2's ``NavigateToPose`` as Jazzy and later distros define it (result ``uint16 error_code``,
#: ``string error_msg``; ``idl/nav2_msgs/action-jazzy/``). On the wire it is the same
#: ``nav2_msgs/action/NavigateToPose`` (:data:`WIRE_NAMES`); in the typestore it has a name of its
#: own, so that one process may encode both.
NAVIGATE_TO_POSE_JAZZY = "nav2_msgs/action/NavigateToPoseJazzy"
#: A typestore name that is not the wire's → (the wire's, the nav2_msgs build that carries it).
WIRE_NAMES = {NAVIGATE_TO_POSE_JAZZY: (NAVIGATE_TO_POSE, "jazzy")}
#: ``[navigation] distro`` → the action type the agent speaks.
NAV2_DISTROS = {"humble": NAVIGATE_TO_POSE, "jazzy": NAVIGATE_TO_POSE_JAZZY}

#: The agent's own (their messages are in ``ros/msg/objsearch_msgs``, registered by ros/types.py).
FIND_OBJECT = "objsearch_msgs/action/FindObject"
WHERE = "objsearch_msgs/srv/Where"


def _read(name: str) -> str:
    wire, variant = WIRE_NAMES.get(name, (name, ""))
    pkg, kind, leaf = wire.split("/")
    folder = f"{kind}-{variant}" if variant else kind
    path = resources.files(__package__).joinpath(IDL_ROOT, pkg, folder, f"{leaf}.{kind}")
    return path.read_text(encoding="utf-8")


def _sections(text: str, count: int) -> list[str]:
    parts: list[list[str]] = [[]]
    for line in text.splitlines():
        if line.strip() == "---":
            parts.append([])
        else:
            parts[-1].append(line)
    if len(parts) != count:
        raise ValueError(f"expected {count} sections separated by ---, found {len(parts)}")
    return ["\n".join(p) + "\n" for p in parts]


class _Builder:
    """Parses ``.msg`` text under names rosbags does not accept (``pkg/srv/…``, ``pkg/action/…``:
    it only knows ``pkg/msg/…``) by parsing under ``pkg/msg/`` and renaming afterwards."""

    def __init__(self) -> None:
        self.types: dict[str, Any] = {}
        self._renames: dict[str, str] = {}

    def add(self, text: str, name: str) -> None:
        pkg, kind, leaf = name.split("/")
        text = "\n".join(
            "uint8" + line[4:] if line.startswith("char") else line for line in text.splitlines()
        )
        self.types.update(get_types_from_msg(text, f"{pkg}/msg/{leaf}"))
        if kind != "msg":
            self._renames[f"{pkg}/msg/{leaf}"] = name

    def _fix(self, node: Any) -> Any:
        kind, detail = node
        if kind == Nodetype.NAME:
            return (kind, self._renames.get(detail, detail))
        if kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
            return (kind, (self._fix(detail[0]), detail[1]))
        return node

    def service(self, name: str, request: str, response: str) -> None:
        leaf = name.rsplit("/", 1)[1]
        self.add(request, f"{name}_Request")
        self.add(response, f"{name}_Response")
        self.add(
            f"service_msgs/ServiceEventInfo info\n{leaf}_Request[<=1] request\n"
            f"{leaf}_Response[<=1] response\n",
            f"{name}_Event",
        )
        self.add(
            f"{leaf}_Request request_message\n{leaf}_Response response_message\n"
            f"{leaf}_Event event_message\n",
            name,
        )

    def action(self, name: str, goal: str, result: str, feedback: str) -> None:
        leaf = name.rsplit("/", 1)[1]
        uuid = "unique_identifier_msgs/UUID goal_id\n"
        self.add(goal, f"{name}_Goal")
        self.add(result, f"{name}_Result")
        self.add(feedback, f"{name}_Feedback")
        self.service(
            f"{name}_SendGoal",
            f"{uuid}{leaf}_Goal goal\n",
            "bool accepted\nbuiltin_interfaces/Time stamp\n",
        )
        self.service(f"{name}_GetResult", uuid, f"int8 status\n{leaf}_Result result\n")
        self.add(f"{uuid}{leaf}_Feedback feedback\n", f"{name}_FeedbackMessage")
        # rosidl's action type description (what ``ros2 action info`` hashes).
        self.add(
            f"{leaf}_Goal goal\n{leaf}_Result result\n{leaf}_Feedback feedback\n"
            f"{leaf}_SendGoal send_goal_service\n{leaf}_GetResult get_result_service\n"
            f"{leaf}_FeedbackMessage feedback_message\n",
            name,
        )

    def result(self) -> dict[str, Any]:
        return {
            self._renames.get(name, name): (consts, [(f, self._fix(n)) for f, n in fields])
            for name, (consts, fields) in self.types.items()
        }


def definitions() -> dict[str, Any]:
    """Every type the ``idl/`` files expand to, as rosbags' typesdict."""
    b = _Builder()
    b.add(_read(SERVICE_EVENT_INFO), SERVICE_EVENT_INFO)
    b.service(CANCEL_GOAL, *_sections(_read(CANCEL_GOAL), 2))
    b.action(NAVIGATE_TO_POSE, *_sections(_read(NAVIGATE_TO_POSE), 3))
    b.action(NAVIGATE_TO_POSE_JAZZY, *_sections(_read(NAVIGATE_TO_POSE_JAZZY), 3))
    b.action(FIND_OBJECT, *_sections(_read(FIND_OBJECT), 3))
    b.service(WHERE, *_sections(_read(WHERE), 2))
    return b.result()


def register(store: Typestore) -> None:
    """Adds what the store lacks (a definition it has is kept: its hash is the real one)."""
    store.register({k: v for k, v in definitions().items() if k not in store.fielddefs})


@cache
def wire_hashes(name: str) -> dict[str, str]:
    """The RIHS01 hashes of an action's parts as its own distro's rosidl computes them (under the
    wire's names): ``{"GetResult_Response": "RIHS01_…", …}``. For a typestore alias
    (:data:`WIRE_NAMES`) they are computed in a store of their own, where the definition has
    the wire's name."""
    from rosbags.typesys import Stores, get_typestore

    from objsearch.ros.types import message_definitions

    wire, _ = WIRE_NAMES.get(name, (name, ""))
    store = get_typestore(Stores.ROS2_HUMBLE)
    extra: dict[str, Any] = {}
    for msg, text in message_definitions().items():
        if msg not in store.fielddefs:
            extra.update(get_types_from_msg(text, msg))
    store.register(extra)
    b = _Builder()
    b.add(_read(SERVICE_EVENT_INFO), SERVICE_EVENT_INFO)
    b.action(wire, *_sections(_read(name), 3))
    store.register({k: v for k, v in b.result().items() if k not in store.fielddefs})
    parts = ("SendGoal", "GetResult", "GetResult_Response", "FeedbackMessage", "Result")
    return {part: str(store.hash_rihs01(f"{wire}_{part}")) for part in parts}
