"""Helpers of the tests (simulated robots, configs, reference encoders, shared fixtures): no tests here."""
