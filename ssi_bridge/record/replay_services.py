"""The replay's player services, named as rosbag2's player names them.

On the replay's node (``/ssi_bridge_replay`` unless ``--ros-args -r __node:=...``):

| service | type | does |
|---|---|---|
| ``~/pause`` | std_srvs/srv/Trigger | stops the time line (success false: already paused) |
| ``~/resume`` | std_srvs/srv/Trigger | runs it again (success false: not paused) |
| ``~/play_next`` | std_srvs/srv/Trigger | publishes the next message at once while paused |
| ``~/set_rate`` | ssi_bridge_msgs/srv/SetRate | speed factor > 0 |
| ``~/seek`` | ssi_bridge_msgs/srv/Seek | a bag time, or seconds from the start |

Every call answers at once with ``success`` and a ``message`` saying what happened or why not;
the callbacks only move the time line (record/player_state.py), so they never block on the
bag. The node must be spun (tools/replay.py runs an executor thread).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from ssi_bridge.record.player_state import NS, PlayerState

if TYPE_CHECKING:
    from rclpy.node import Node


def _at(state: PlayerState, bag_ns: int) -> str:
    """``12.345 s into the bag`` for messages."""
    return f"{(bag_ns - state.first_ns) / NS:.3f} s into the bag"


class ReplayServices:
    """Creates the player services of ``node`` on ``state``; keeps them alive."""

    def __init__(self, node: Node, state: PlayerState) -> None:
        from ssi_bridge_msgs.srv import Seek, SetRate
        from std_srvs.srv import Trigger

        self.state = state
        self.services = [
            node.create_service(Trigger, "~/pause", self._pause),
            node.create_service(Trigger, "~/resume", self._resume),
            node.create_service(Trigger, "~/play_next", self._play_next),
            node.create_service(SetRate, "~/set_rate", self._set_rate),
            node.create_service(Seek, "~/seek", self._seek),
        ]

    def _pause(self, _request: Any, response: Any) -> Any:
        response.success = self.state.pause()
        response.message = ("paused at " if response.success else "already paused at ") + \
            _at(self.state, self.state.snapshot().bag_ns)
        return response

    def _resume(self, _request: Any, response: Any) -> Any:
        response.success = self.state.resume()
        response.message = ("playing from " if response.success else "not paused; at ") + \
            _at(self.state, self.state.snapshot().bag_ns)
        return response

    def _play_next(self, _request: Any, response: Any) -> Any:
        response.success = self.state.step()
        response.message = ("the next message is published" if response.success else
                            "play_next works while paused (call ~/pause first)"
                            if not self.state.snapshot().ended else "the replay has ended")
        return response

    def _set_rate(self, request: Any, response: Any) -> Any:
        try:
            self.state.set_rate(request.rate)
        except ValueError as err:
            response.success, response.message = False, str(err)
            return response
        response.success, response.message = True, f"rate {request.rate:g}"
        return response

    def _seek(self, request: Any, response: Any) -> Any:
        stamp = request.time.sec * NS + request.time.nanosec
        if stamp == 0 and request.offset < 0:
            response.success = False
            response.message = f"offset {request.offset}: must be >= 0"
            return response
        wanted = stamp if stamp else self.state.first_ns + round(request.offset * NS)
        target = self.state.seek(wanted)
        response.success = True
        response.message = f"playing from {_at(self.state, target)}" + (
            " (clamped into the bag)" if target != wanted else "")
        return response
