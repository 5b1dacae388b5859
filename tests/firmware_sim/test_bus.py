import errno

import pytest
from smbus2 import i2c_msg

from firmware_sim.bus import SimBus
from firmware_sim.clock import VirtualClock


class Ram:
    """Pointer + auto-increment memory: a generic I2C EEPROM-like target."""

    def __init__(self):
        self.mem = bytearray(range(256))
        self.ptr = 0
        self.writes = []

    def i2c_write(self, data):
        self.writes.append(bytes(data))
        if data:
            self.ptr = data[0]
            for b in data[1:]:
                self.mem[self.ptr] = b
                self.ptr = (self.ptr + 1) & 0xFF

    def i2c_read(self, n):
        out = bytes(self.mem[(self.ptr + i) & 0xFF] for i in range(n))
        self.ptr = (self.ptr + n) & 0xFF
        return out


@pytest.fixture
def setup():
    clock = VirtualClock()
    bus = SimBus(1, clock=clock, rng=7)
    ram = bus.attach(0x50, Ram())
    return clock, bus, ram


def test_byte_access(setup):
    _, bus, ram = setup
    bus.write_byte(0x50, 0x10)
    assert bus.read_byte(0x50) == 0x10
    bus.write_byte_data(0x50, 0x20, 0xAB)
    assert ram.mem[0x20] == 0xAB
    assert bus.read_byte_data(0x50, 0x20) == 0xAB


def test_word_data_is_little_endian_on_the_wire(setup):
    _, bus, ram = setup
    ram.mem[0x30:0x32] = b"\x01\x90"          # a big-endian chip register 0x0190
    assert bus.read_word_data(0x50, 0x30) == 0x9001
    bus.write_word_data(0x50, 0x40, 0x1234)
    assert ram.writes[-1] == bytes([0x40, 0x34, 0x12])


def test_i2c_block_access_and_limit(setup):
    _, bus, ram = setup
    bus.write_i2c_block_data(0x50, 0x60, [1, 2, 3])
    assert bus.read_i2c_block_data(0x50, 0x60, 3) == [1, 2, 3]
    assert bus.read_i2c_block_data(0x50, 0x00, 32) == list(range(32))
    with pytest.raises(ValueError, match="over 32"):
        bus.read_i2c_block_data(0x50, 0, 33)
    with pytest.raises(ValueError, match="cannot exceed 32"):
        bus.write_i2c_block_data(0x50, 0, [0] * 33)
    with pytest.raises(ValueError, match="cannot exceed 32"):
        bus.write_block_data(0x50, 0, [0] * 33)


def test_smbus_block_and_process_call(setup):
    _, bus, ram = setup
    bus.write_block_data(0x50, 0x70, [9, 8, 7])
    assert ram.writes[-1] == bytes([0x70, 3, 9, 8, 7])   # count byte precedes data
    assert bus.read_block_data(0x50, 0x70) == [9, 8, 7]  # first byte read is the count
    # process call: word written low byte first, then a word read (little-endian)
    assert bus.process_call(0x50, 0x80, 0x1234) == 0x8382
    assert ram.mem[0x80:0x82] == b"\x34\x12"
    bus.write_quick(0x50)
    with pytest.raises(OSError):
        bus.write_quick(0x51)


def test_i2c_rdwr_fills_read_buffers(setup):
    _, bus, ram = setup
    wr = i2c_msg.write(0x50, [0x05])
    rd = i2c_msg.read(0x50, 4)
    bus.i2c_rdwr(wr, rd)
    assert list(rd) == [5, 6, 7, 8]
    assert bytes(rd) == b"\x05\x06\x07\x08"
    bus.i2c_rdwr(i2c_msg.write(0x50, [0x90, 0xEE]))
    assert ram.mem[0x90] == 0xEE
    with pytest.raises(TypeError):
        bus.i2c_rdwr(object())


@pytest.mark.parametrize("call", [
    lambda b: b.read_byte(0x51),
    lambda b: b.read_byte_data(0x51, 0),
    lambda b: b.read_i2c_block_data(0x51, 0, 2),
    lambda b: b.i2c_rdwr(i2c_msg.read(0x51, 1)),
])
def test_absent_address_raises_remote_io_error(setup, call):
    _, bus, _ = setup
    with pytest.raises(OSError) as ei:
        call(bus)
    assert ei.value.errno == errno.EREMOTEIO


def test_generic_adapter_errno_enxio():
    bus = SimBus(nack_errno=errno.ENXIO)
    with pytest.raises(OSError) as ei:
        bus.read_byte(0x20)
    assert ei.value.errno == errno.ENXIO


def test_context_manager_closes_and_open_reopens(setup):
    _, bus, _ = setup
    with bus as b:
        assert b.read_byte_data(0x50, 3) == 3
    assert bus.closed
    with pytest.raises(OSError) as ei:
        bus.read_byte(0x50)
    assert ei.value.errno == errno.EBADF
    bus.open(1)
    assert bus.read_byte_data(0x50, 4) == 4


def test_smbus2_compat_attributes(setup):
    _, bus, _ = setup
    assert bus.pec == 0
    bus.pec = 1
    assert bus.pec == 1
    assert bus.read_byte_data(0x50, 1, force=True) == 1
    with pytest.raises(ValueError):
        bus.write_byte(0x50, 256)
    with pytest.raises(ValueError):
        bus.attach(0x50, Ram())
    with pytest.raises(ValueError):
        bus.attach(0x80, Ram())


def test_nack_window_on_virtual_clock(setup):
    clock, bus, _ = setup
    bus.nack(0x50, from_s=1.0, until_s=2.0)
    assert bus.read_byte_data(0x50, 1) == 1
    clock.advance(1.0)
    with pytest.raises(OSError) as ei:
        bus.read_byte_data(0x50, 1)
    assert ei.value.errno == errno.EREMOTEIO
    clock.advance(1.0)
    assert bus.read_byte_data(0x50, 1) == 1
    assert bus.stats["nack"] == 1


def test_stuck_bus_times_out_everything(setup):
    clock, bus, _ = setup
    bus.stuck(from_s=0.5)
    bus.read_byte(0x50)
    clock.advance(0.5)
    for call in (lambda: bus.read_byte(0x50), lambda: bus.write_byte(0x51, 0),
                 lambda: bus.i2c_rdwr(i2c_msg.read(0x50, 1))):
        with pytest.raises(OSError) as ei:
            call()
        assert ei.value.errno == errno.ETIMEDOUT
    bus.clear_faults()
    bus.read_byte(0x50)


def test_flaky_is_seeded_and_probabilistic():
    def run():
        bus = SimBus(rng=123)
        bus.attach(0x50, Ram())
        bus.flaky(0.3, 0x50)
        fails = 0
        for _ in range(400):
            try:
                bus.read_byte_data(0x50, 0)
            except OSError as e:
                assert e.errno == errno.EREMOTEIO
                fails += 1
        return fails
    a, b = run(), run()
    assert a == b                       # reproducible
    assert 80 < a < 160                 # ~30 % of 400


def test_flaky_reads_only_spares_writes():
    bus = SimBus(rng=1)
    ram = bus.attach(0x50, Ram())
    bus.flaky(1.0, 0x50, reads_only=True)
    bus.write_byte_data(0x50, 0x10, 0x42)
    assert ram.mem[0x10] == 0x42
    with pytest.raises(OSError):
        bus.read_byte(0x50)
    with pytest.raises(ValueError):
        bus.flaky(1.5)


def test_bit_rate_advances_clock():
    clock = VirtualClock()
    bus = SimBus(clock=clock, bit_rate_Hz=100e3)
    bus.attach(0x50, Ram())
    bus.read_i2c_block_data(0x50, 0, 2)   # addr+reg, addr+2 bytes = 5 bytes
    assert clock.now() == pytest.approx((9 * 5 + 4) / 100e3)


def test_method_set_and_signatures_match_smbus2():
    import inspect

    import smbus2

    public = [n for n, f in inspect.getmembers(smbus2.SMBus, inspect.isfunction) if not n.startswith("_")]
    for name in public + ["__enter__", "__exit__"]:
        assert hasattr(SimBus, name), name
        ours = list(inspect.signature(getattr(SimBus, name)).parameters)
        theirs = list(inspect.signature(getattr(smbus2.SMBus, name)).parameters)
        assert ours == theirs, name
    assert isinstance(SimBus.pec, property)


def test_block_process_call(setup):
    _, bus, ram = setup
    ram.mem[0xA2:0xA5] = bytes([2, 0x11, 0x22])
    # writes reg 0xA0 <- count 1, 0xA1 <- 0x55; then reads from 0xA2: count 2, data
    assert bus.block_process_call(0x50, 0xA0, [0x55]) == [0x11, 0x22]
