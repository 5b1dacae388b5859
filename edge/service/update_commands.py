"""The daemon's requests that change what it runs on: configuration, model, object sets, calibration.

CONFIG_GET/SET (runtime keys only, validated, persisted atomically), MODEL_BEGIN/CHUNK/COMMIT/ABORT
(verified atomic install through :class:`edge.model.store.ModelStore`, :mod:`edge.service.upload`),
OBJECTS_BEGIN/CHUNK/COMMIT/ABORT/LIST/REMOVE/SELECT (:mod:`edge.service.objects`) and
CALIBRATION_SET/GET (:mod:`edge.service.calibration`). One mixin per group.
"""

from __future__ import annotations

import logging

from edge.protocol.errors import CommandError, ErrorCode
from edge.service.config import ConfigError
from edge.service.requests import config_reply
from edge.service.status_commands import State

__all__ = [
    "ConfigCommands", "ModelCommands", "ObjectSetCommands", "CalibrationCommands",
]

log = logging.getLogger("thermotouch.edge")

class ConfigCommands:
    """CONFIG_GET and CONFIG_SET (the latter only while idle or in fault).

    Mixed into :class:`edge.service.daemon.Daemon`, whose constructor sets the attributes used
    here; the methods are the daemon's own (``self`` is the daemon).
    """

    def _cmd_config_get(self, args: dict) -> dict:
        keys = args.get("keys")
        try:
            values = self.config.flat(keys)
        except ConfigError as e:
            raise CommandError(ErrorCode.BAD_ARGUMENT, str(e), e.key) from None
        return config_reply(values, self.max_payload)

    def _cmd_config_set(self, args: dict) -> dict:
        values = args["values"]
        if self.state not in (State.IDLE, State.FAULT):
            raise CommandError(ErrorCode.BUSY, f"cannot change the configuration while {self.state}")
        try:
            new = self.config.with_updates(values)
        except ConfigError as e:
            raise CommandError(ErrorCode.BAD_ARGUMENT, str(e), e.key) from None
        self.overrides.save(new, self.base_config)
        self.config = new
        self._apply_logging()
        log.info("configuration changed: %s", {k: new.get(k) for k in values})
        return config_reply(new.flat(), self.max_payload)


class ModelCommands:
    """MODEL_BEGIN/CHUNK/COMMIT/ABORT: a model upload in chunks, installed atomically at commit.

    Mixed into :class:`edge.service.daemon.Daemon`, whose constructor sets the attributes used
    here; the methods are the daemon's own (``self`` is the daemon).
    """

    def _cmd_model_begin(self, args: dict) -> dict:
        out = self.upload.begin(args["size"], args["sha256"], args.get("version"), args.get("downgrade"))
        return {**out, "session": self.upload.session}

    def _cmd_model_chunk(self, args: dict) -> dict:
        return self.upload.chunk(args["offset"], args["data"], args.get("session"), require_session=True)

    def _cmd_model_commit(self, args: dict) -> dict:
        return self.upload.commit(args.get("session"), require_session=True)

    def _cmd_model_abort(self, args: dict) -> dict:
        return self.upload.abort(args.get("session"), require_session=True)


class ObjectSetCommands:
    """OBJECTS_*: the user's object sets (upload, list, remove, select); the ``objects`` fault re-checked at once.

    Mixed into :class:`edge.service.daemon.Daemon`, whose constructor sets the attributes used
    here; the methods are the daemon's own (``self`` is the daemon).
    """

    def _cmd_objects_begin(self, args: dict) -> dict:
        return self.objects.begin(args["name"], args["size"], args["sha256"], args.get("activate", True),
                                  signature=None if args.get("signature") is None
                                  else args["signature"].encode("utf-8"))

    def _cmd_objects_chunk(self, args: dict) -> dict:
        return self.objects.chunk(args["offset"], args["data"], args["session"])

    def _cmd_objects_commit(self, args: dict) -> dict:
        try:
            return self.objects.commit(args["session"])
        finally:
            self._check_objects()  # the set in use may have changed: say so now, not at the next re-check

    def _cmd_objects_abort(self, args: dict) -> dict:
        return self.objects.abort(args.get("session"))

    def _cmd_objects_list(self, args: dict) -> dict:
        return self.objects.listing()

    def _cmd_objects_remove(self, args: dict) -> dict:
        try:
            return self.objects.remove(args["name"])
        finally:
            self._check_objects()  # the set in use may have changed: say so now, not at the next re-check

    def _cmd_objects_select(self, args: dict) -> dict:
        try:
            return self.objects.select(args["name"])
        finally:
            self._check_objects()  # the set in use may have changed: say so now, not at the next re-check


class CalibrationCommands:
    """CALIBRATION_SET (refused while measuring) and CALIBRATION_GET.

    Mixed into :class:`edge.service.daemon.Daemon`, whose constructor sets the attributes used
    here; the methods are the daemon's own (``self`` is the daemon).
    """

    def _cmd_calibration_set(self, args: dict) -> dict:
        if self.measuring:
            raise CommandError(ErrorCode.BUSY, "a measurement is running")
        return self.calibration.install(args["calibration"], args.get("signature"))

    def _cmd_calibration_get(self, args: dict) -> dict:
        return self.calibration.get()
