"""Drivers are tested on the simulator's board: real gpiod/PWM semantics, no hardware."""

import pytest

from firmware_sim.board import make_sim_board


@pytest.fixture
def board():
    """A fresh simulated board (GPIO chip, PWM tree, virtual clock), closed after the test."""
    b = make_sim_board()
    yield b
    b.close()
