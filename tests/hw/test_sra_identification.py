"""The soft-arm identification core without ROS: replay, recording checks, the fit."""

from dataclasses import replace

import numpy as np
import pytest

from inflarm_hw.sra_identification import (
    IDENTIFIED_FIELDS,
    PlantRecording,
    identify_plant,
    replay_recording,
)
from inflarm_hw.sra_plant import NOISE_FREE
from sra_recording import plant_run


def test_the_replay_is_the_plant_run_itself():
    recording, truth = plant_run(NOISE_FREE, 8.0, seed=7)
    replayed = replay_recording(NOISE_FREE, recording)
    np.testing.assert_allclose(replayed.positions, truth, atol=1e-12)
    np.testing.assert_allclose(replayed.pressures, recording.pressures, atol=1e-6)


def test_a_recording_with_nan_or_unordered_times_is_rejected_naming_the_series():
    t = np.arange(3.0)
    good5, good3 = np.zeros((3, 5)), np.zeros((3, 3))
    bad = good3.copy()
    bad[1, 2] = np.nan
    with pytest.raises(ValueError, match=r'positions: 1 samples hold NaN .* t = 1.000 s'):
        PlantRecording(t, good5, t, good5, t, bad)
    with pytest.raises(ValueError, match='expected pressures times in increasing order'):
        PlantRecording(t, good5, t[::-1], good5, t, good3)
    with pytest.raises(ValueError, match=r'commands .* values of shape \(k, 5\)'):
        PlantRecording(t, good3, t, good5, t, good3)


def test_identify_plant_rejects_an_unknown_field():
    recording, _ = plant_run(NOISE_FREE, 2.0, seed=7)
    with pytest.raises(ValueError, match="got \\['pba_length'\\]"):
        identify_plant(recording, NOISE_FREE, fields=('pba_length',))


def test_a_noise_free_run_gives_back_its_plant():
    true = replace(NOISE_FREE, valve_delay=0.14, pea_modulus=60e3, bellows_time_constant=0.4)
    recording, _ = plant_run(true, 12.0, seed=11)
    fit = identify_plant(recording, NOISE_FREE, fields=IDENTIFIED_FIELDS)
    assert fit.converged, fit.message
    for field, value in zip(fit.fields, fit.values, strict=True):
        assert value == pytest.approx(getattr(true, field), rel=1e-3), field
    assert fit.position_rms.max() < 1e-5 and fit.pressure_rms.max() < 1.0
