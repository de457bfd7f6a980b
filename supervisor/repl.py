"""The console loop: lines from a person (or stdin of a script) to supervisor runs.

A reader thread takes lines as they come; commands run one after the other on a worker thread, so
that "stop" typed while an action runs aborts it (at its next service call or trajectory chunk) and
the progress of the running action keeps showing. At the end of the input the loop waits for the
commands already given, then returns 0 if the last command succeeded (1 if it failed, was refused, or
asked a question the input did not answer).
"""

from __future__ import annotations

import queue
import sys
import threading
from collections import deque
from collections.abc import Iterable
from typing import IO

from services.errors import HumanoidError
from supervisor.console import Command, Listener, help_text
from supervisor.core import Supervisor
from supervisor.script import EITHER_HAND


class ConsoleLoop:
    """Reads commands from ``lines`` and runs them on ``sup``; messages to ``out``."""

    def __init__(
        self,
        sup: Supervisor,
        known_objects: list[str],
        out: IO[str],
        *,
        hand: str = EITHER_HAND,
        prompt: bool = False,
    ) -> None:
        self.sup = sup
        self.known = known_objects
        self.out = out
        self.hand = hand
        self.prompt = prompt
        self.last_ok: bool | None = None
        self.last_refused = False  # the last command line heard was not understood (exit code 1)
        self._pending: deque[Command] = deque()
        self._worker: threading.Thread | None = None
        self._count = 0
        self.listener = Listener(known_objects, hand)  # the conversation: "it", questions and answers

    def say(self, text: str) -> None:
        self.out.write(text + "\n")
        self.out.flush()

    def run(self, lines: Iterable[str]) -> int:
        inbox: queue.Queue[str | None] = queue.Queue()

        def read() -> None:
            try:
                for line in lines:
                    inbox.put(line)
            finally:
                inbox.put(None)

        threading.Thread(target=read, name="console-reader", daemon=True).start()
        self.say(f"Ready. Objects I know: {', '.join(k.replace('_', ' ') for k in self.known)}. Say 'help'.")
        self._show_prompt()
        finished_input = False
        while True:
            if self._worker is not None and not self._worker.is_alive():
                self._worker = None
                self._show_prompt()
            if self._worker is None and self._pending:
                self._start(self._pending.popleft())
            if finished_input and self._worker is None and not self._pending:
                break
            try:
                line = inbox.get(timeout=0.05)
            except queue.Empty:
                continue
            if line is None:
                finished_input = True
                continue
            if not self._handle(line):
                break
        if self._worker is not None:
            self._worker.join()
        if self.listener.asking:  # the input ended on a question: what it asked for was not done
            self.say("(the input ended without an answer: nothing done for the last command)")
            return 1
        return 0 if self.last_ok in (None, True) and not self.last_refused else 1

    def _handle(self, line: str) -> bool:
        """Process one line; False to quit."""
        if not line.strip() or line.lstrip().startswith("#"):
            return True
        command = self.listener.hear(line)
        if command.say:
            self.say(command.say)
        # whatever runs or waits: piped lines are all heard before the first command ends
        self.last_refused = command.refused
        if command.refused or command.control == "ask":
            self._show_prompt()
            return True
        if command.control == "help":
            self.say(help_text())
        elif command.control == "stop":
            self._pending.clear()
            if self._worker is not None:
                self.say("stopping")
                self.sup.request_stop()
            else:
                self.say("nothing is running")
        elif command.control == "quit":
            self._pending.clear()
            if self._worker is not None:
                self.sup.request_stop()
            return False
        elif command.steps:
            self._pending.append(command)
        return True

    def _start(self, command: Command) -> None:
        self._count += 1
        run_id = f"console:{self._count}"

        def work() -> None:
            try:
                report = self.sup.run(command.steps, run_id=run_id)
                self.last_ok = report.ok
                if not report.ok:
                    self.listener.forget_held()
                failure = report.failure
                if failure is not None and failure.reason == "not_found":
                    self.say(f"I could not find it: {failure.message}")
            except HumanoidError as exc:
                self.last_ok = False
                self.say(f"error: {exc.code}: {exc.message}")

        self._worker = threading.Thread(target=work, name="console-command", daemon=True)
        self._worker.start()

    def _show_prompt(self) -> None:
        if self.prompt:
            self.out.write("> ")
            self.out.flush()


def stdin_lines() -> Iterable[str]:
    for line in sys.stdin:
        yield line.rstrip("\n")
