"""The words a measurement record is described with: its status, why it ended, its quality flags.

They are :class:`enum.StrEnum` members, so each one *is* its string: the
wire protocol, the JSON replies and the history database carry the same
``"ok"``, ``"no_contact"`` ... as before, and a record read back from the
database (plain strings) compares equal to the members.

This module sits below everything that uses these words -- the measurement
sequence makes statuses, reasons and flags, the estimator adds flags, the
history validates statuses, the daemon compares reasons -- and imports
nothing from edge, so none of those packages has to import another just to
spell a flag.
"""

from __future__ import annotations

from enum import StrEnum

__all__ = ["Status", "Reason", "Flag"]


class Status(StrEnum):
    """How a measurement ended (``status`` of a record)."""

    #: Measured and estimated.
    OK = "ok"
    #: Cut short by a safety limit or a stop; :class:`Reason` says which.
    ABORTED = "aborted"
    #: Sensor fault, heater fault, estimator crash or a bug; the raw data is kept.
    FAILED = "failed"


class Reason(StrEnum):
    """Why a measurement did not end ``ok`` (``reason`` of a record)."""

    #: The abort event was set (daemon stopping, SIGTERM/SIGINT).
    STOPPED = "stopped"
    #: The heater was found off mid-heating with no watchdog trip recorded.
    HEATER_CUT = "heater_cut"
    #: Heating would have run past ``heater.max_on_time_s``.
    MAX_ON_TIME = "max_on_time"
    #: The thermocouple read above ``heater.over_temperature_C``.
    OVER_TEMPERATURE = "over_temperature"
    #: A sensor did not answer or read a non-finite value.
    SENSOR_FAULT = "sensor_fault"
    #: The thermocouple converter reports an open junction.
    OPEN_THERMOCOUPLE = "open_thermocouple"
    #: The heater could not be switched off, or it heats when commanded off or not when on
    #: (measurements stop until restart).
    HEATER_FAULT = "heater_fault"
    #: An unexpected exception in the sequence.
    INTERNAL = "internal"
    #: The heating phase gave too few samples to resample.
    TOO_FEW_SAMPLES = "too_few_samples"
    #: The estimator raised (the heater was already off).
    ESTIMATION_FAILED = "estimation_failed"
    #: The host sent ABORT (e.g. Ctrl-C or its own timeout): heater cut at once, record kept.
    HOST_ABORT = "host_abort"
    #: Armed (``arm_s``): no contact came within the arming time; the heater never went on.
    NO_CONTACT = "no_contact"


class Flag(StrEnum):
    """Quality flags a record can carry (``flags`` of a record and of an estimate)."""

    # -- from the measurement sequence (thresholds in ``[measurement]``)
    #: The effusivity the heating record shows (flux vs temperature rise) is below
    #: ``no_contact_e_W_s05_m2K``, i.e. nearer still air's than any solid's: the probe was not touching.
    #: Touch again with the face flat on the object for the whole contact time.
    NO_CONTACT = "no_contact"
    #: An ADC clipped during the run: the clipped readings are not the signal.  Lower the heater power
    #: (``--voltage``/``--power``) and touch again.
    SATURATED = "saturated"
    #: Baseline scatter above ``noise_T_K`` or ``noise_q_W_m2``: the answer scatters more than its u says.
    #: Keep the probe and its cable still, away from drafts and switching supplies, and touch again.
    NOISY = "noisy"
    #: Baseline drift above ``unstable_baseline_K``: the probe or the object was not at a steady temperature.
    #: Let both settle at the room's temperature (or rest the probe after the last touch) and touch again.
    UNSTABLE_BASELINE = "unstable_baseline"
    #: Heating stopped before the contact time because the answer was decided (MEASURE ``until_decided``).
    #: Nothing to do; measure without ``--until-decided`` to heat for the whole contact time.
    DECIDED = "decided"
    #: Heating stopped early on a running answer that the full estimate does not confirm (another
    #: object): the running estimate is the thick-body model on the raw thermopile reading, while the
    #: result may be the calibrated sensor chain's.  The result is the answer; the decision is kept.
    #: If the object matters, touch again without ``--until-decided``.
    DECISION_DISAGREES = "decision_disagrees"
    #: The heater does not follow its command (see ``heater.fault_flux_W_m2``): the run is failed.
    #: Stop measuring and check the heater and its wiring (``thermotouch info`` lists the fault).
    HEATER_FAULT = "heater_fault"
    # -- from the estimator
    #: No usable temperature rise at all.  Check the contact and that the heater runs, then touch again.
    NO_SIGNAL = "no_signal"
    #: Too little temperature rise for the default method.  Raise the heater power or the contact time.
    INSUFFICIENT_SIGNAL = "insufficient_signal"
    #: The features lie outside the model's training range: the answer is an extrapolation.  Check it
    #: against a reference of known value, or use a model trained for this range.
    OUTSIDE_TRAINING_RANGE = "outside_training_range"
    #: The heater power lies outside the model's training range.  Measure at a power inside it.
    POWER_OUTSIDE_TRAINING_RANGE = "power_outside_training_range"
    #: A feature was clipped to the model's input range: the answer lies at the model's edge.  Treat it
    #: as a bound and check it against a reference.
    FEATURE_CLIPPED = "feature_clipped"
    #: The best diffusivity sits at the end of the scanned range: alpha (and k) is a bound, not a value.
    #: A longer contact time (``--time``) can resolve it.
    ALPHA_AT_SCAN_EDGE = "alpha_at_scan_edge"
    #: The touch did not resolve k and alpha separately: they come from the library prior given e
    #: (the result's ``prior_reason`` says why).  e is this touch's own; a longer contact time can resolve k
    #: and alpha.
    K_ALPHA_FROM_PRIOR = "k_alpha_from_prior"
    #: The object's stated thickness does not show in the record (the heat has not reached its back):
    #: k and alpha come from the prior, not from the thickness.  Heat longer, or measure without it.
    THICKNESS_UNRESOLVED = "thickness_unresolved"
    #: The iterative fit stopped before it converged.  Touch again; if it persists, keep the record
    #: (``thermotouch history --export``) for a report.
    NOT_CONVERGED = "not_converged"
    # -- from the calibrated sensor chain and the seam (edge.estimation.seam)
    #: No calibration for this probe head is installed: the answer uses the datasheet's sensor chain,
    #: whose flux sensitivity, sensing depth and bead lag are off by tens of percent on a real probe.
    #: Calibrate the probe on reference materials (``thermotouch calibrate``) and install the result.
    UNCALIBRATED = "uncalibrated"
    #: The sensor chain's fit leaves a residual well above the noise measured in air (normalised residual
    #: above ``chain_estimate.POOR_FIT``): the chain does not describe this record (a moving probe, a
    #: contact that changed, a record cut short).  Its e is not the answer; touch again, holding still.
    POOR_FIT = "poor_fit"
    #: The sensor chain could not be fitted at all (no positive effusivity fits the record): the answer,
    #: if any, is the method's own.  Touch again; if it persists check the flux sensor's wiring.
    NO_FIT = "no_fit"
    #: The probe left the object while the heater was on (the face flux collapsed): every answer of this
    #: record is suspect and the chain gives none.  Touch again and keep the probe on the object until
    #: the measurement ends.
    CONTACT_LOST = "contact_lost"
    #: The finite heater's sideways loss moved e by more than 10 % (``chain_estimate.LATERAL_FLAG``): the
    #: answer rests on the object's alpha and on the object being much larger than the heater.  Prefer a
    #: larger object, or check the answer against one of known size.
    LATERAL_SPREAD = "lateral_spread"
    #: The record has no samples of the probe in air before the contact: the contact instant and the
    #: probe's initial state are guessed, and u(e) carries the change of e with the fit's start.  Arm
    #: the measurement (``--arm``) and touch after it starts, so the contact is recorded.
    CONTACT_NOT_RECORDED = "contact_not_recorded"
