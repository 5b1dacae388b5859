"""Simulated sysfs PWM tree (kernel rules, raw-write policing, duty history) and the edge SysfsPwm driver."""

import errno
import gc
import os

import pytest

from edge.hw.sysfs_pwm import OsSysfsIO, PwmError, SysfsPwm
from firmware_sim.clock import VirtualClock
import firmware_sim.pwm as pwm_mod
from firmware_sim.pwm import SimPwmTree


@pytest.fixture
def tree():
    clock = VirtualClock()
    t = SimPwmTree(clock, chips={0: 2})
    yield t
    t.close()


def ch(tree, name, channel=0):
    return tree.channel_dir(0, channel) / name


def exported(tree, channel=0):
    tree.io.write(tree.chip_dir(0) / "export", f"{channel}\n")
    return tree


def errno_of(fn):
    with pytest.raises(OSError) as ei:
        fn()
    return ei.value.errno


# ---- tree layout and export rules


def test_layout_and_export_unexport(tree):
    assert (tree.chip_dir(0) / "npwm").read_text() == "2\n"
    assert not tree.channel_dir(0, 0).exists()
    exported(tree)
    assert {p.name for p in tree.channel_dir(0, 0).iterdir()} == {"period", "duty_cycle", "enable", "polarity"}
    assert tree.io.read(ch(tree, "period")) == "0\n" and tree.io.read(ch(tree, "polarity")) == "normal\n"
    assert errno_of(lambda: tree.io.write(tree.chip_dir(0) / "export", "0")) == errno.EBUSY
    assert errno_of(lambda: tree.io.write(tree.chip_dir(0) / "export", "2")) == errno.ENODEV
    tree.io.write(tree.chip_dir(0) / "unexport", "0")
    assert not tree.channel_dir(0, 0).exists() and not tree.is_exported(0, 0)
    assert errno_of(lambda: tree.io.write(tree.chip_dir(0) / "unexport", "0")) == errno.ENODEV
    assert errno_of(lambda: tree.io.write(tree.chip_dir(0) / "npwm", "4")) == errno.EACCES
    assert errno_of(lambda: tree.io.read(ch(tree, "period"))) == errno.ENOENT


def test_paths_are_resolved_once_and_outside_paths_still_refused(tree, tmp_path):
    """A path's place in the tree is kept (resolving was most of the simulated PWM's cost): a symlink to
    the tree reaches the same channel, a path outside it or climbing out with '..' is refused every time."""
    exported(tree)
    link = tmp_path / "class_pwm"
    link.symlink_to(tree.root, target_is_directory=True)
    tree.io.write(link / "pwmchip0" / "pwm0" / "period", "1000\n")
    assert tree.io.read(ch(tree, "period")) == "1000\n" == tree.io.read(link / "pwmchip0" / "pwm0" / "period")
    outside = tmp_path / "period"
    climbing = tree.channel_dir(0, 0) / ".." / ".." / ".." / "period"
    for _ in range(2):   # the second time from what was kept
        assert errno_of(lambda: tree.io.read(outside)) == errno.ENOENT
        assert errno_of(lambda: tree.io.read(climbing)) == errno.ENOENT
    tree.io.write(tree.chip_dir(0) / "unexport", "0")   # a kept path of an unexported channel is not an attribute
    assert errno_of(lambda: tree.io.read(link / "pwmchip0" / "pwm0" / "period")) == errno.ENOENT


def test_temporary_root_is_removed_on_close():
    t = SimPwmTree(VirtualClock())
    root = t.root
    assert root.is_dir()
    t.close()
    assert not root.exists()
    t.close()  # idempotent


def test_a_tree_nobody_closed_is_removed_when_it_is_collected():
    clock = VirtualClock()
    t = SimPwmTree(clock)
    root = t.root
    del t, clock  # the clock holds the tree's advance hook: both go
    gc.collect()
    assert not root.exists()


def test_a_forked_child_never_removes_its_parents_trees():
    # A test's daemon runs in a forked child that inherits the parent's simulator objects; its
    # collector running their finalizers deleted the parent's files (and, counted as file operations,
    # made the kill-point tests nondeterministic).
    clock = VirtualClock()
    t = SimPwmTree(clock)
    root = t.root
    pid = os.fork()
    if pid == 0:   # the child drops and collects its copy, then leaves without running exit handlers
        code = 0
        try:
            del t, clock  # the clock holds the tree's advance hook: both go
            gc.collect()
        except BaseException:
            code = 1
        finally:
            os._exit(code)
    _, status = os.waitpid(pid, 0)
    assert os.waitstatus_to_exitcode(status) == 0
    assert root.is_dir() and (root / "pwmchip0").is_dir()
    t.close()
    assert not root.exists() and clock is not None


def test_a_caller_supplied_root_is_never_removed(tmp_path):
    t = SimPwmTree(VirtualClock(), tmp_path / "sys")
    t.close()
    assert (tmp_path / "sys" / "pwmchip0").is_dir()


# ---- kernel value rules through the synchronous io route


def test_duty_and_enable_need_a_period(tree):
    exported(tree)
    assert errno_of(lambda: tree.io.write(ch(tree, "duty_cycle"), "10")) == errno.EINVAL
    assert errno_of(lambda: tree.io.write(ch(tree, "enable"), "1")) == errno.EINVAL
    assert ch(tree, "enable").read_text() == "0\n"


def test_duty_above_period_rejected_and_file_unchanged(tree):
    exported(tree)
    tree.io.write(ch(tree, "period"), "1000")
    tree.io.write(ch(tree, "duty_cycle"), "400")
    with pytest.raises(OSError) as ei:
        tree.io.write(ch(tree, "duty_cycle"), "1001")
    assert ei.value.errno == errno.EINVAL and ei.value.filename.endswith("duty_cycle")
    assert ch(tree, "duty_cycle").read_text() == "400\n"
    # Shrinking the period below the duty cycle is refused as well.
    assert errno_of(lambda: tree.io.write(ch(tree, "period"), "300")) == errno.EINVAL
    assert tree.state().period_ns == 1000


@pytest.mark.parametrize("attr,text", [("enable", "2"), ("period", "-5"), ("period", "abc"),
                                       ("polarity", "upside-down")])
def test_malformed_values_are_einval(tree, attr, text):
    exported(tree)
    tree.io.write(ch(tree, "period"), "1000")
    assert errno_of(lambda: tree.io.write(ch(tree, attr), text)) == errno.EINVAL


def test_a_write_rewrites_only_the_attribute_it_changed_and_keeps_a_raw_write_made_before(tree):
    exported(tree)
    tree.io.write(ch(tree, "period"), "1000")
    before = {n: os.stat(ch(tree, n)).st_mtime_ns for n in ("period", "enable", "polarity")}
    os.utime(ch(tree, "period"), ns=(1, 1))   # a marker: a rewrite of the file would move it
    tree.io.write(ch(tree, "duty_cycle"), "400")
    assert os.stat(ch(tree, "period")).st_mtime_ns == 1
    assert all(os.stat(ch(tree, n)).st_mtime_ns == before[n] for n in ("enable", "polarity"))
    # A raw write just before an accepted one is applied (the write syncs first), not overwritten.
    ch(tree, "period").write_text("2000\n")
    tree.io.write(ch(tree, "duty_cycle"), "1500")
    assert tree.state()[1:3] == (2000, 1500)
    assert [ch(tree, n).read_text() for n in ("period", "duty_cycle", "enable", "polarity")] == \
        ["2000\n", "1500\n", "0\n", "normal\n"]
    assert tree.violations == []


def test_history_and_duty_at(tree):
    clock = tree.clock
    exported(tree)
    tree.io.write(ch(tree, "period"), "1000000")
    tree.io.write(ch(tree, "duty_cycle"), "250000")
    clock.advance(1.0)
    tree.io.write(ch(tree, "enable"), "1")
    clock.advance(2.0)
    tree.io.write(ch(tree, "enable"), "0")
    tree.io.write(ch(tree, "polarity"), "inversed")
    tree.io.write(ch(tree, "enable"), "1")
    assert tree.duty_at(0.5) == 0.0  # not enabled yet
    assert tree.duty_at(1.0) == 0.25 and tree.duty_at(2.9) == 0.25
    assert tree.duty_at(3.0) == 0.75  # inversed polarity
    hist = tree.history()
    assert [(h.t_s, h.enabled) for h in hist[-4:]] == [(1.0, True), (3.0, False), (3.0, False), (3.0, True)]


def test_unexport_does_not_stop_the_output(tree):
    exported(tree)
    tree.io.write(ch(tree, "period"), "1000")
    tree.io.write(ch(tree, "duty_cycle"), "500")
    tree.io.write(ch(tree, "enable"), "1")
    tree.io.write(tree.chip_dir(0) / "unexport", "0")
    assert tree.duty_at(tree.clock.now()) == 0.5


# ---- raw file writes: policed on each clock advance


def test_raw_valid_writes_are_applied_at_the_write_time(tree):
    clock = tree.clock
    (tree.chip_dir(0) / "export").write_text("1\n")
    clock.advance(0.5)
    assert tree.channel_dir(0, 1).is_dir()
    ch(tree, "period", 1).write_text("2000\n")
    ch(tree, "duty_cycle", 1).write_text("500\n")
    ch(tree, "enable", 1).write_text("1\n")
    clock.advance(1.0)  # the writes happened at t = 0.5
    assert tree.state(0, 1)[:4] == (0.5, 2000, 500, True)
    assert tree.duty_at(0.6, 0, 1) == 0.25
    assert tree.violations == []


def test_raw_invalid_write_is_reverted_and_recorded(tree):
    clock = tree.clock
    exported(tree)
    tree.io.write(ch(tree, "period"), "1000")
    ch(tree, "duty_cycle").write_text("5000\n")
    clock.advance(0.1)
    assert ch(tree, "duty_cycle").read_text() == "0\n"
    assert tree.state().duty_ns == 0
    (v,) = tree.violations
    assert v.path.endswith("duty_cycle") and v.value == "5000\n" and "duty_cycle" in v.reason
    (tree.chip_dir(0) / "export").write_text("7\n")
    clock.advance(0.1)
    assert len(tree.violations) == 2 and tree.violations[1].value == "7"


@pytest.fixture(params=["inotify", "reading"])
def watched_tree(request, monkeypatch):
    """A tree whose syncs skip unchanged files (inotify), and one whose syncs read them all."""
    if request.param == "reading":
        monkeypatch.setattr(pwm_mod, "_dir_watch", lambda: None)
    elif pwm_mod._dir_watch() is None:
        pytest.skip("no inotify here")
    t = SimPwmTree(VirtualClock(), chips={0: 2})
    yield t
    t.close()


def test_raw_writes_after_many_quiet_syncs_are_seen_whatever_the_route(watched_tree):
    tree = watched_tree
    clock = tree.clock
    exported(tree)
    tree.io.write(ch(tree, "period"), "1000")
    for _ in range(5):
        clock.advance(0.01)          # quiet steps: nothing changed
    ch(tree, "duty_cycle").write_text("400\n")                   # in place
    clock.advance(0.01)
    assert tree.state().duty_ns == 400
    for _ in range(3):
        clock.advance(0.01)
    tmp = tree.channel_dir(0, 0) / ".enable.tmp"                 # a replacement by rename
    tmp.write_text("1\n")
    os.replace(tmp, ch(tree, "enable"))
    clock.advance(0.01)
    assert tree.state().enabled
    t_rm = clock.now()
    for name in ("period", "duty_cycle", "enable", "polarity"):    # the channel's directory removed
        ch(tree, name).unlink()
    tree.channel_dir(0, 0).rmdir()
    clock.advance(0.01)   # removed files read as empty values: refused, recorded, and the files restored
    assert [ch(tree, n).read_text() for n in ("period", "duty_cycle", "enable")] == ["1000\n", "400\n", "1\n"]
    assert {v.t_s for v in tree.violations} == {t_rm}
    for _ in range(3):
        clock.advance(0.01)
    ch(tree, "duty_cycle").write_text("5000\n")                  # and still watched afterwards
    clock.advance(0.01)
    assert ch(tree, "duty_cycle").read_text() == "400\n" and tree.violations[-1].value == "5000\n"
    (tree.chip_dir(0) / "export").write_text("1\n")             # the chip's own files
    clock.advance(0.01)
    assert tree.is_exported(0, 1)
    ch(tree, "period", 1).write_text("3000\n")                   # a channel exported by a raw write
    clock.advance(0.01)
    assert tree.state(0, 1).period_ns == 3000


def test_a_forked_childs_raw_write_reaches_the_parents_tree_and_its_own(watched_tree):
    tree = watched_tree
    exported(tree)
    tree.io.write(ch(tree, "period"), "1000")
    tree.clock.advance(0.01)
    pid = os.fork()
    if pid == 0:   # the child syncs its inherited copy of the tree, then writes a raw value
        code = 1
        try:
            tree.clock.advance(0.01)
            ch(tree, "duty_cycle").write_text("300\n")
            tree.clock.advance(0.01)
            code = 0 if tree.state().duty_ns == 300 else 2
        finally:
            os._exit(code)
    _, status = os.waitpid(pid, 0)
    assert os.waitstatus_to_exitcode(status) == 0
    tree.clock.advance(0.01)
    assert tree.state().duty_ns == 300


def test_a_lost_inotify_instance_falls_back_to_reading_every_file(monkeypatch):
    monkeypatch.setattr(pwm_mod, "_WATCH", None)       # this test's own instance (the process's is kept)
    monkeypatch.setattr(pwm_mod, "_WATCH_PID", None)
    watch = pwm_mod._dir_watch()
    if watch is None:
        pytest.skip("no inotify here")
    tree = SimPwmTree(VirtualClock(), chips={0: 2})
    try:
        exported(tree)
        tree.io.write(ch(tree, "period"), "1000")
        tree.clock.advance(0.01)
        os.close(watch.fd)                               # closed under it
        ch(tree, "duty_cycle").write_text("600\n")
        tree.clock.advance(0.01)
        assert tree.state().duty_ns == 600 and pwm_mod._dir_watch() is None
    finally:
        tree.close()


# ---- the edge driver on the simulated tree


def pwm_on(tree, **kw):
    return SysfsPwm(tree.root, 0, 0, io=tree.io, clock=tree.clock, **kw)


def test_driver_open_configure_enable_close(tree):
    pwm = pwm_on(tree)
    pwm.open()
    assert tree.is_exported()
    pwm.configure(1_000_000, 300_000)
    pwm.enable()
    assert pwm.read_state() == (1_000_000, 300_000, True, "normal")
    assert pwm.set_duty_fraction(0.5) == 500_000
    assert tree.duty_at(tree.clock.now()) == 0.5
    pwm.open()  # already exported: no EBUSY
    pwm.close(unexport=True)
    assert not tree.is_exported() and tree.state().enabled is False


@pytest.mark.parametrize("steps", [
    [(1000, 900), (100, 50)],          # shrink below the old duty: duty must go first
    [(100, 50), (10_000, 9_000)],      # grow above the old period: period must go first
    [(1000, 0), (1000, 1000), (500, 500), (2000, 1)],
])
def test_driver_configure_orders_writes_for_the_kernel(tree, steps):
    pwm = pwm_on(tree)
    pwm.open()
    for period, duty in steps:
        pwm.configure(period, duty)  # the io raises if any intermediate state were invalid
        assert (pwm.period_ns, pwm.duty_ns) == (period, duty)


def test_driver_refuses_bad_requests_before_writing(tree):
    pwm = pwm_on(tree)
    pwm.open()
    with pytest.raises(PwmError, match="period"):
        pwm.enable()
    with pytest.raises(PwmError, match="period"):
        pwm.set_duty_ns(5)
    with pytest.raises(ValueError, match="duty_ns"):
        pwm.configure(100, 101)
    with pytest.raises(ValueError, match="period_ns"):
        pwm.configure(0, 0)
    with pytest.raises(ValueError, match="fraction"):
        pwm.set_duty_fraction(1.5)
    assert tree.history()[-1].period_ns == 0


def test_driver_reports_kernel_rejection_naming_the_file(tree):
    pwm = pwm_on(tree)
    pwm.open()
    pwm.configure(1000, 500)
    with pytest.raises(PwmError) as ei:
        pwm._write_checked("period", 10)  # bypass the driver's own ordering
    assert ei.value.path.endswith("pwm0/period") and ei.value.errno == errno.EINVAL
    assert "period" in str(ei.value) and "Invalid argument" in str(ei.value)


def test_driver_read_back_detects_a_value_not_taken(tree):
    class Clamping:
        """An io whose 'kernel' rounds periods to multiples of 1000 ns."""

        def read(self, path):
            return tree.io.read(path)

        def write(self, path, text):
            if str(path).endswith("period"):
                text = str(int(text) // 1000 * 1000)
            tree.io.write(path, text)

    pwm = SysfsPwm(tree.root, 0, 0, io=Clamping(), clock=tree.clock)
    pwm.open()
    with pytest.raises(PwmError, match="read back '1000'"):
        pwm.configure(1500, 0)


def test_driver_with_plain_file_io_waits_for_export_in_virtual_time(tree):
    pwm = SysfsPwm(tree.root, 0, 1, io=OsSysfsIO(), clock=tree.clock, poll_interval_s=0.01)
    pwm.open()  # the raw export is only seen by the tree once the clock moves
    assert tree.is_exported(0, 1) and tree.clock.now() == pytest.approx(0.01)
    pwm.configure(2000, 1000)
    pwm.enable()
    tree.clock.advance(0.1)
    assert tree.violations == [] and tree.state(0, 1)[1:4] == (2000, 1000, True)


def test_driver_missing_chip_and_export_timeout(tree):
    with pytest.raises(PwmError, match="pwmchip3") as ei:
        SysfsPwm(tree.root, 3, 0, io=tree.io, clock=tree.clock).open()
    assert ei.value.path.endswith("pwmchip3")
    with pytest.raises(PwmError, match="npwm"):
        SysfsPwm(tree.root, 0, 5, io=tree.io, clock=tree.clock).open()

    class SwallowsExport:
        def read(self, path):
            return tree.io.read(path)

        def write(self, path, text):
            pass

    pwm = SysfsPwm(tree.root, 0, 0, io=SwallowsExport(), clock=tree.clock, export_timeout_s=0.5)
    with pytest.raises(PwmError, match="did not become writable"):
        pwm.open()
    assert tree.clock.now() == pytest.approx(0.5, abs=0.02)
