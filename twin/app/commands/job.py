"""The skeleton every many-run command shares (sweep, montecarlo, validate, falsify, certify): its parameters
and spread, the checks before the work, its served clients (``--serve``), the writing of ``--out``, and the
lines and exit codes of a job that was interrupted, lost its client or whose controller failed.

A command builds one ``ManyRunJob`` from its typed options record and runs its own work in between; the
skeleton's messages and exit codes are written here once. Nothing heavy is imported at the top.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

from twin.app.commands.common import (
    OutputOptions,
    ParamsOptions,
    ServedOptions,
    SpreadOptions,
    check_overwrite,
    controller_failures,
    inputs,
    interrupted,
    load_params,
    package_version,
    params_and_spread,
    refuse_unused,
    screen_audit_failure,
    served_stopped,
    write_out,
)
from twin.outputs import JobFiles, check_output_folder

if TYPE_CHECKING:
    from twin.app.fanout import Served
    from twin.app.montecarlo import Distribution
    from twin.parameters import Parameters

# A job that serves no client (falsify, certify: a search or a statement runs here).
NOT_SERVED = ServedOptions(serve=None, timeout=None, wait_client=None)


class JobOptions(Protocol):
    """What every many-run command's record gives its job (``ManyRunJob.of``)."""

    @property
    def controller(self) -> str | None: ...
    @property
    def workers(self) -> int: ...
    @property
    def controller_timeout(self) -> float | None: ...
    @property
    def parameters(self) -> ParamsOptions: ...
    @property
    def spread(self) -> SpreadOptions: ...
    @property
    def output(self) -> OutputOptions: ...


@dataclass(frozen=True)
class ManyRunJob:
    """One many-run job of ``command``: what it reads (its controller, parameters, rigs and the files named by
    ``criteria`` and ``spec``), where it runs (``workers``, ``scheduler``) and what it writes (``output``)."""

    command: str
    controller: str | None
    parameters: ParamsOptions
    rigs: SpreadOptions
    output: OutputOptions
    workers: int = 1
    scheduler: str | None = None
    served: ServedOptions = NOT_SERVED
    controller_timeout: float | None = None
    criteria: str | None = None
    spec: str | None = None

    @classmethod
    def of(
        cls,
        command: str,
        options: JobOptions,
        *,
        scheduler: str | None = None,
        served: ServedOptions = NOT_SERVED,
        criteria: str | None = None,
        spec: str | None = None,
    ) -> ManyRunJob:
        """The job of ``command`` from its record's common fields and what only some commands have."""
        return cls(
            command,
            options.controller,
            options.parameters,
            options.spread,
            options.output,
            workers=options.workers,
            scheduler=scheduler,
            served=served,
            controller_timeout=options.controller_timeout,
            criteria=criteria,
            spec=spec,
        )

    @property
    def is_served(self) -> bool:
        return self.served.serve is not None

    def check_served(self) -> None:
        """The options that go with --serve or without it (a ParameterError: exit 2)."""
        from twin.parameters import ParameterError

        if self.served.serve is None:
            if self.controller is None:
                raise ParameterError("--controller is required (unless --serve: the client's controller)")
            for option, value in (
                ("--timeout", self.served.timeout),
                ("--wait-client", self.served.wait_client),
            ):
                if value is not None:
                    raise ParameterError(f"{option} is a served job's wait: it needs --serve")
            return
        _serve_address(self.served.serve)
        if self.workers > 1 or self.scheduler is not None:
            raise ParameterError(
                "--serve runs every session here, one after the other on one socket: drop --workers/--scheduler"
            )
        if self.controller_timeout is not None:
            raise ParameterError("--controller-timeout: with --serve the client's budget is --timeout")

    def params(self) -> Parameters:
        """The parameters (--params/--set) of a job without rigs drawn."""
        return load_params(self.parameters)

    def params_and_spread(self) -> tuple[Parameters, Distribution | None]:
        """The parameters and the rigs' spread (a calibration brings both)."""
        return params_and_spread(self.parameters, self.rigs)

    def inputs(self) -> list[tuple[str, str]]:
        """The files the job reads: no output may replace one."""
        return inputs(
            params=self.parameters.params,
            rig_file=self.parameters.rig_file,
            spread=self.rigs.spread,
            criteria=self.criteria,
            spec=self.spec,
            calibration=self.rigs.calibration,
            controller=self.controller,
        )

    def check(self, params: Parameters, outputs: JobFiles) -> None:
        """What every many-run job checks before the work (its numbers are checked by their types): the
        controller (built once: a failing constructor is refused here) and the output folder it writes
        ``outputs`` into."""
        from twin.app.hosts import catalogue_for

        if not self.is_served:  # served: the client's controller is none of ours
            assert self.controller is not None  # required unless served (check_served)
            catalogue_for(self.controller, params)
        out = self.output
        check_overwrite(out.overwrite, [("--out", out.out)])
        if self.scheduler is not None:  # the scheduler's workers run the job, not local ones
            refuse_unused(
                [("--workers", self.workers if self.workers > 1 else None)],
                f"--scheduler {self.scheduler} fans the runs out to its own workers: drop one",
            )
        if out.out is not None:
            check_output_folder("--out", out.out, outputs, overwrite=out.overwrite, inputs=self.inputs())

    @contextmanager
    def serving(self, params: Parameters) -> Iterator[Served | None]:
        """With --serve: the job's server (one socket for all its sessions, bound before the work; its URL
        printed first), closed after the job; else None."""
        if self.served.serve is None:
            yield None
            return
        from twin.app.fanout import Served
        from twin.parameters import ParameterError
        from twin.serving.server import DEFAULT_TIMEOUT_S, ServeError, Server, SessionSettings

        host, port = _serve_address(self.served.serve)
        settings = SessionSettings(
            params=params, rig_name=f"ballbeam-twin {package_version()} {self.command}"
        )
        try:
            server = Server(settings, host, port)
        except ServeError as exc:
            raise ParameterError(f"--serve {self.served.serve}: {exc}") from None
        timeout_s = self.served.timeout if self.served.timeout is not None else DEFAULT_TIMEOUT_S
        wait_client = self.served.wait_client
        with server:
            # The address first; with --json stdout is JSON lines (this one, then the job's summary).
            address = (
                json.dumps({"serving_on": server.url}) if self.output.json else f"serving on {server.url}"
            )
            print(address, flush=True)
            yield Served(
                server,
                timeout_s=timeout_s,
                first_wait_s=wait_client,
                next_wait_s=wait_client if wait_client is not None else timeout_s,
            )

    @property
    def name(self) -> str:
        """What the report calls the controller: --controller, else (served) a placeholder until the client
        has said its name (``client_name``)."""
        return str(self.controller) if self.controller is not None else "served client"

    def client_name(self, served: Served | None) -> str | None:
        """A served job without --controller: the clients' HELLO names, which the report then carries."""
        if served is None or self.controller is not None:
            return None
        return ", ".join(served.client_names()) or "served client (none came)"

    def write(self, write: Callable[..., Any], result: Any) -> None:
        """The result written to --out (checked before the job)."""
        write_out(self.output.out, self.output.overwrite, write, result)

    def stopped(self, served: Served | None, done: int, total: int) -> int | None:
        """1 with a line on stderr when a served job ended for want of a client; else None."""
        return served_stopped(served, self.command, done, total)

    def interrupted(self, what: str, name: str = "") -> int:
        """An interrupted job: what it kept (``what``), in --out's ``name``; 128 + the signal."""
        return interrupted(self.command, what, self.output.out, name)

    def audit_failed(self, screening: dict[str, Any] | None) -> bool:
        """True, with the line on stderr, when a screened job's audit found runs MuJoCo classes otherwise."""
        if screening is not None and (wrong := screening["audit"]["mismatches"]):
            print(screen_audit_failure(self.command, wrong), file=sys.stderr)
            return True
        return False

    def failures(self, records: Sequence[dict[str, Any] | None]) -> int:
        """0, or 1 with a line on stderr when the controller failed in some runs."""
        return controller_failures(records, self.command)


def _serve_address(text: str) -> tuple[str, int]:
    """--serve's ``[HOST:]PORT`` (a bare port: 127.0.0.1, this machine only)."""
    from twin.parameters import ParameterError

    host, colon, port_text = text.rpartition(":")
    host = host.strip("[]") if colon else "127.0.0.1"  # [::1]:PORT
    port = int(port_text) if port_text.isdigit() else -1
    if not 0 <= port <= 65535 or not host:
        raise ParameterError(f"--serve {text!r}: expected [HOST:]PORT, a UDP port 0…65535 (0: a free one)")
    return host, port
