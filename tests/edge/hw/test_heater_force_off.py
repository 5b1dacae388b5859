"""The heater is driven off without a board: at daemon start-up and by ExecStopPost."""

from firmware_sim.clock import VirtualClock
from firmware_sim.gpiod.kernel import GpioSim
from firmware_sim.pwm import SimPwmTree
from edge.hw.board import GpioLine, force_rpi_heater_off
from edge.hw.sysfs_pwm import SysfsPwm


def _left_on(clock):
    """A heater left on by a process that died: line active and released, PWM enabled at 50 %."""
    gpio = GpioSim(clock)
    chip = gpio.add_chip("/dev/gpiochip0")
    tree = SimPwmTree(clock, chips={0: 2})
    GpioLine(gpio.gpiod, "/dev/gpiochip0", 17).request_output("dead-daemon", value=True).release()
    pwm = SysfsPwm(tree.root, 0, 0, io=tree.io, clock=clock)
    pwm.open()
    pwm.configure(1_000_000, 500_000)
    pwm.enable()
    clock.advance(0.1)
    assert chip.level_at(17, clock.now()) == 1 and tree.duty_at(clock.now()) == 0.5
    return gpio, chip, tree


def test_force_off_cuts_line_and_pwm():
    clock = VirtualClock()
    gpio, chip, tree = _left_on(clock)
    failures = force_rpi_heater_off(gpiod_module=gpio.gpiod, pwm_root=str(tree.root), pwm_io=tree.io)
    clock.advance(0.1)
    assert failures == []
    assert chip.level_at(17, clock.now()) == 0
    assert tree.duty_at(clock.now()) == 0.0
    assert not tree.state().enabled
    tree.close()


def test_force_off_tries_pwm_when_gpio_fails():
    clock = VirtualClock()
    gpio, chip, tree = _left_on(clock)
    failures = force_rpi_heater_off(gpiod_module=gpio.gpiod, gpio_chip="/dev/gpiochip9", pwm_root=str(tree.root),
                                    pwm_io=tree.io)
    clock.advance(0.1)
    assert len(failures) == 1 and "gpiochip9" in failures[0]
    assert tree.duty_at(clock.now()) == 0.0
    tree.close()


def test_force_off_tries_gpio_when_pwm_missing(tmp_path):
    clock = VirtualClock()
    gpio, chip, tree = _left_on(clock)
    (tmp_path / "pwmchip0" / "pwm0").mkdir(parents=True)  # exported but unreadable: no period file
    failures = force_rpi_heater_off(gpiod_module=gpio.gpiod, pwm_root=str(tmp_path))
    clock.advance(0.1)
    assert len(failures) == 1 and "PWM" in failures[0]
    assert chip.level_at(17, clock.now()) == 0
    tree.close()


def test_daemon_heater_off_mode(tmp_path, capsys):
    from edge.service.main import main

    sim = tmp_path / "sim.toml"
    sim.write_text('[board]\nkind = "sim"\n')
    assert main(["--config", str(sim), "--heater-off"]) == 0
    # A real board on a machine without GPIO: the failure is reported, not hidden.
    rpi = tmp_path / "rpi.toml"
    rpi.write_text(f'[board]\nkind = "rpi"\ngpio_chip = "{tmp_path}/gpiochip0"\npwm_root = "{tmp_path}/pwm"\n')
    assert main(["--config", str(rpi), "--heater-off"]) == 1
