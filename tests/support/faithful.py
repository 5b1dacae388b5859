"""The faithful (r, z) world's time step in tests."""

#: Time step of the faithful world in every test that does not choose one.  The simulator marches at
#: 10 ms; TR-BDF2 is second order in time (tests/firmware_sim/rz/test_world.py observes it) and the
#: tolerances the tests assert hold at 20 ms as well (40 ms breaks the provisional-step test), which
#: costs about a third less CPU in the suite's faithful-world tests.  The benches keep the
#: simulator's own step.  ``tests/conftest.py`` applies it to every test.
TEST_DT_s = 0.02
