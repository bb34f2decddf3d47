"""The recorder's services: ``~/start_recording``, ``~/stop_recording``, rosbag2's
``~/pause_recording``, ``~/resume_recording``, ``~/split_recording``, and ``~/snapshot``.

Each handler turns a request into a call of the session recorder (``ros/recording.py``) or
its fault snapshots (``ros/snapshot.py``) and answers ``success: false`` with the reason
instead of raising; the node's request queue serves them like every other service
(``ros/services.py``).
"""

from __future__ import annotations

from collections.abc import Callable

from ssi_bridge_msgs.srv import StartRecording, StopRecording
from std_srvs.srv import Trigger

from ssi_bridge.exceptions import RecordingError
from ssi_bridge.ros.recording import SessionRecorder


class RecorderServices:
    """The handlers of the recorder's services.

    :param recorder: the node's session recorder (and its snapshots)
    """

    def __init__(self, recorder: SessionRecorder) -> None:
        self._recorder = recorder

    def on_start(self, request: StartRecording.Request,
                 response: StartRecording.Response) -> StartRecording.Response:
        """~/start_recording: a new bag (``request.path``: its name; empty: timestamped)."""
        try:
            response.bag_directory = str(self._recorder.start(request.path))
            response.success, response.message = True, f"recording to {response.bag_directory}"
        except (RecordingError, OSError, ValueError) as err:
            response.success, response.message = False, f"start_recording: {err}"
        return response

    def on_stop(self, request: StopRecording.Request,
                response: StopRecording.Response) -> StopRecording.Response:
        """~/stop_recording: close the session's bag; its directory and message count."""
        try:
            done = self._recorder.stop()
        except (RecordingError, OSError) as err:
            response.success, response.message = False, f"stop_recording: {err}"
            return response
        if done is None:
            response.success, response.message = False, "stop_recording: no recording is running"
            return response
        response.bag_directory, response.message_count = str(done[0]), done[1]
        response.success = True
        response.message = f"closed {done[0]} with {done[1]} messages"
        return response

    def on_pause(self, request: Trigger.Request, response: Trigger.Response
                 ) -> Trigger.Response:
        """~/pause_recording (std_srvs/Trigger)."""
        return _answer(response, "pause_recording", lambda: self._recorder.set_paused(True))

    def on_resume(self, request: Trigger.Request, response: Trigger.Response
                  ) -> Trigger.Response:
        """~/resume_recording (std_srvs/Trigger)."""
        return _answer(response, "resume_recording", lambda: self._recorder.set_paused(False))

    def on_split(self, request: Trigger.Request, response: Trigger.Response
                 ) -> Trigger.Response:
        """~/split_recording (std_srvs/Trigger): the message names the new file."""
        return _answer(response, "split_recording", lambda: f"writing {self._recorder.split()}")

    def on_snapshot(self, request: Trigger.Request, response: Trigger.Response
                    ) -> Trigger.Response:
        """~/snapshot (std_srvs/Trigger): write the ring now (or extend the one running)."""
        def snapshot() -> str:
            if self._recorder.finalized:
                raise RecordingError("the node is finalized (lifecycle shutdown)")
            if self._recorder.snapshots is None:
                raise RecordingError("record.snapshot.duration is 0: no ring is kept; set it "
                                     "(seconds before a snapshot) to take snapshots")
            return self._recorder.snapshots.on_request()
        return _answer(response, "snapshot", snapshot)


def _answer(response: Trigger.Response, kind: str,
            action: Callable[[], str]) -> Trigger.Response:
    """Fill a Trigger response from ``action()`` (its text) or the refusal."""
    try:
        response.success, response.message = True, action()
    except (RecordingError, OSError, ValueError) as err:
        response.success, response.message = False, f"{kind}: {err}"
    return response


__all__ = ["RecorderServices"]
