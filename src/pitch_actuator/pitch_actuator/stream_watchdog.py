"""When the simulated actuator stops waiting for commands and lives on in real time.

The simulated actuator is reactive: experiment time advances with the command stamps, so a
slow or paused graph is harmless. It must still behave like the rig when the command stream is
really gone, so without commands it steps its model in real time (the governor holds, then
ramps to the safe angle), but only

- after ``lost_timeout_s`` (the governor's watchdog timeout) once no command publisher is left
  in the graph (DDS matching: the generator has exited or was killed), or
- after ``stream_timeout_s`` of wall time without a command although a publisher is still
  there (a hung generator), or
- at once (two samples) after a stop request, which needs no stream to act.

Every sample stepped this way is a *free-run* sample: the experiment did not ask for it, and
the node reports the episode as an anomaly (rig_runtime.anomaly). Plain logic with explicit
wall times, tested in-process.
"""

from dataclasses import dataclass

MAX_STEPS_PER_CALL = 50  # a late timer catches up in bounded bursts


@dataclass
class SilentStreamWatchdog:
    fs: float
    stream_timeout_s: float
    lost_timeout_s: float
    last_command_wall: float | None = None
    self_steps: int = 0  # samples stepped without commands since the last command

    def command(self, wall_s: float) -> bool:
        """A command arrived; returns True if it ends a free-run episode."""
        ended = self.self_steps > 0
        self.last_command_wall = wall_s
        self.self_steps = 0
        return ended

    @property
    def running_on(self) -> bool:
        return self.self_steps > 0

    def timeout(self, publisher_present: bool, stopped: bool) -> float:
        timeout = self.stream_timeout_s
        if not publisher_present:
            timeout = min(timeout, self.lost_timeout_s)
        if stopped:
            timeout = min(timeout, 2.0 / self.fs)
        return timeout

    def silent_s(self, wall_s: float) -> float:
        return 0.0 if self.last_command_wall is None else wall_s - self.last_command_wall

    def due(self, wall_s: float, publisher_present: bool, stopped: bool) -> int:
        """Samples to step on the actuator's own clock now (0 while commands are awaited).

        Before the first command there is no experiment time to run on: nothing is due.
        """
        if self.last_command_wall is None:
            return 0
        timeout = self.timeout(publisher_present, stopped)
        silent = self.silent_s(wall_s)
        if silent < timeout:
            return 0
        due = int((silent - timeout) * self.fs) + 1 - self.self_steps
        return max(0, min(due, MAX_STEPS_PER_CALL))

    def stepped(self, n: int = 1) -> None:
        self.self_steps += n
