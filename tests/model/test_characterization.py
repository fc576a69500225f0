"""Tests of inflarm_model.characterization and the inflarm-characterize CLI (sections 3-4)."""

import csv
import io
import math

import numpy as np
import pytest

from inflarm_model.characterization import (
    SAMPLES_HEADER,
    TABLE3_CSV_HEADER,
    CantileverSamples,
    PressureFit,
    SamplesFormatError,
    angle_and_torque,
    characterize,
    fit_pressure,
    read_samples_csv,
    synthetic_samples,
    table3_csv,
    table3_markdown,
    write_samples_csv,
)
from inflarm_model.characterize_cli import main
from inflarm_model.link import LINK_RADIUS, TABLE3, wrinkling_moment

PNG_MAGIC = b'\x89PNG\r\n\x1a\n'


@pytest.fixture(scope='module')
def synthetic():
    samples = synthetic_samples(np.random.default_rng(7))
    return samples, characterize(samples)


# --- angle and torque ----------------------------------------------------------------------------

def test_angle_and_torque_use_the_lever_arm_about_the_prb_hinge():
    rng = np.random.default_rng(7)
    theta = rng.uniform(0.0, 0.15, 20)
    force = rng.uniform(0.0, 40.0, 20)
    h, l1 = 0.5, 0.03
    angle, torque = angle_and_torque(theta * (h - l1), force, h, l1)
    np.testing.assert_allclose(angle, theta, rtol=1e-12)
    np.testing.assert_allclose(torque, force * 0.47, rtol=1e-12)
    # Small-angle approximation against the exact geometry of the rotating body.
    exact_v = (h - l1) * np.tan(theta)
    angle_from_exact, _ = angle_and_torque(exact_v, force, h, l1)
    np.testing.assert_allclose(angle_from_exact, theta, rtol=0.01)


@pytest.mark.parametrize(('kwargs', 'match'), [
    (dict(displacement=np.nan, force=1.0), 'displacement must be finite'),
    (dict(displacement=0.01, force=1.0, probe_distance=0.03, spring_offset=0.03),
     'probe_distance must be greater than spring_offset'),
    (dict(displacement=0.01, force=1.0, spring_offset=-0.01), 'spring_offset must be non-neg'),
    (dict(displacement=[0.01, 0.02], force=[1.0, 2.0, 3.0]), 'broadcastable shapes'),
])
def test_angle_and_torque_rejects_bad_input(kwargs, match):
    with pytest.raises(ValueError, match=match):
        angle_and_torque(**kwargs)


# --- fit at one pressure -------------------------------------------------------------------------

def test_fit_is_exact_on_a_noise_free_bilinear_characteristic():
    p, k, m_max = 30e3, 160.0, 14.0
    m_w = float(wrinkling_moment(p, LINK_RADIUS))
    theta = np.linspace(0.002, 0.2, 60)
    fit = fit_pressure(theta, np.minimum(k * theta, m_max), p)
    assert fit.pressure == p
    np.testing.assert_allclose(fit.stiffness, k, rtol=1e-12)
    assert fit.stiffness_std < 1e-9
    # Samples at or above M_w average the ramp between M_w and M_max with the plateau.
    above = np.minimum(k * theta, m_max)[k * theta >= m_w]
    np.testing.assert_allclose(fit.max_moment, np.mean(above), rtol=1e-12)
    assert fit.n_linear == np.sum(k * theta < m_w) and fit.n_linear + fit.n_saturated == 60
    np.testing.assert_allclose(fit.wrinkling_moment, m_w)


def test_fit_goes_through_the_origin():
    # An offset in the data is not absorbed by an intercept: the slope is sum(xy) / sum(x²).
    theta = np.linspace(0.01, 0.05, 5)
    fit = fit_pressure(theta, 100.0 * theta + 0.5, 60e3)
    np.testing.assert_allclose(fit.stiffness, np.sum(theta * (100.0 * theta + 0.5))
                               / np.sum(theta**2))
    assert fit.stiffness > 100.0 and fit.max_moment is None and fit.n_saturated == 0


def test_fit_standard_error_matches_the_scatter_of_repeated_fits():
    rng = np.random.default_rng(7)
    theta = np.linspace(0.005, 0.1, 20)
    fits = [fit_pressure(theta, 170.0 * theta + rng.normal(0.0, 0.8, 20), 60e3)
            for _ in range(400)]
    slopes = np.array([f.stiffness for f in fits])
    errors = np.array([f.stiffness_std for f in fits])
    expected = 0.8 / math.sqrt(np.sum(theta**2))
    np.testing.assert_allclose(np.mean(slopes), 170.0, atol=3.0 * expected / 20.0)
    np.testing.assert_allclose(np.std(slopes), expected, rtol=0.1)
    np.testing.assert_allclose(np.mean(errors), expected, rtol=0.05)


def test_bilinear_characteristic_saturates_at_m_max():
    fit = PressureFit(40e3, 170.0, 5.0, 18.0, 16.4, 10, 5)
    np.testing.assert_allclose(fit.torque([-1.0, 0.0, 0.05, 1.0]), [-18.0, 0.0, 8.5, 18.0])
    linear = PressureFit(60e3, 170.0, 5.0, None, 24.6, 10, 0)
    np.testing.assert_allclose(linear.torque(1.0), 170.0)


@pytest.mark.parametrize(('args', 'match'), [
    (([0.01], [1.0], 60e3), 'need at least 2 samples'),
    (([0.01, 0.2, 0.3], [1.0, 30.0, 50.0], 10e3), 'need at least 2 samples'),
    (([0.0, 0.0], [0.0, 0.0], 10e3), 'non-zero angle'),
    (([0.01, 0.02], [1.0], 10e3), 'same shape'),
    (([0.01, np.inf], [1.0, 2.0], 10e3), 'must be finite'),
    (([0.01, 0.02], [1.0, 2.0], -10e3), 'pressure must be positive'),
])
def test_fit_rejects_bad_input(args, match):
    with pytest.raises(ValueError, match=match):
        fit_pressure(*args)


# --- synthetic samples and Table 3 ---------------------------------------------------------------

@pytest.mark.parametrize('i', range(len(TABLE3)), ids=lambda i: f'{TABLE3[i].pressure / 1e3:g}kPa')
def test_fit_of_synthetic_samples_recovers_table3(synthetic, i):
    _, fits = synthetic
    fit, row = fits[i], TABLE3[i]
    assert fit.pressure == row.pressure
    assert abs(fit.stiffness - row.stiffness) <= 2.0 * row.stiffness_std
    assert 0.5 * row.stiffness_std <= fit.stiffness_std <= 2.0 * row.stiffness_std
    assert abs(fit.wrinkling_moment - row.wrinkling_moment) <= 0.01
    if row.max_moment is None:
        assert fit.max_moment is None and fit.n_saturated == 0
    else:
        np.testing.assert_allclose(fit.max_moment, row.max_moment, rtol=0.05)
        assert fit.max_moment > fit.wrinkling_moment


def test_synthetic_samples_are_seeded_and_stay_below_mw_at_60_kpa(synthetic):
    samples, _ = synthetic
    again = synthetic_samples(np.random.default_rng(7))
    other = synthetic_samples(np.random.default_rng(8))
    np.testing.assert_array_equal(again.force, samples.force)
    assert not np.allclose(other.force, samples.force)
    _, tau = angle_and_torque(samples.displacement, samples.force, samples.probe_distance,
                              samples.spring_offset)
    at_60 = samples.pressure == 60e3
    assert np.sum(at_60) > 0 and np.all(tau[at_60] < wrinkling_moment(60e3, LINK_RADIUS))
    assert set(np.unique(samples.pressure)) == {row.pressure for row in TABLE3}


def test_grouping_tolerates_pressure_sensor_jitter(synthetic):
    samples, fits = synthetic
    jitter = np.random.default_rng(7).uniform(-300.0, 300.0, len(samples))
    jittered = CantileverSamples(samples.pressure + jitter, samples.displacement,
                                 samples.force, samples.probe_distance, samples.spring_offset)
    again = characterize(jittered)
    assert [f.pressure for f in again] == [f.pressure for f in fits]
    np.testing.assert_allclose([f.stiffness for f in again], [f.stiffness for f in fits])
    with pytest.raises(ValueError, match='rounds pressure .* to zero'):
        characterize(jittered, pressure_step=1e6)


def test_table3_markdown_reproduces_the_paper_table():
    text = table3_markdown(TABLE3)
    lines = text.strip().splitlines()
    assert len(lines) == 2 + len(TABLE3)
    assert '| 10 | 182.56 | 3.37 | 4.99 | 4.11 |' in lines
    assert '| 60 | 166.66 | 4.99 | N/A | 24.63 |' in lines


def test_table3_csv_parses_back_to_the_fits(synthetic):
    _, fits = synthetic
    rows = list(csv.DictReader(io.StringIO(table3_csv(fits))))
    assert tuple(rows[0]) == TABLE3_CSV_HEADER and len(rows) == len(fits)
    for row, fit in zip(rows, fits, strict=True):
        assert float(row['pressure_pa']) == fit.pressure
        assert float(row['stiffness_nm_per_rad']) == fit.stiffness
        assert float(row['stiffness_std_nm_per_rad']) == fit.stiffness_std
        assert (row['max_moment_nm'] == '') == (fit.max_moment is None)
        assert int(row['n_linear']) == fit.n_linear


# --- samples CSV ---------------------------------------------------------------------------------

def test_samples_csv_round_trips_exactly(tmp_path, synthetic):
    samples, _ = synthetic
    path = tmp_path / 'samples.csv'
    write_samples_csv(path, samples)
    assert path.read_text().splitlines()[0] == ','.join(SAMPLES_HEADER)
    back = read_samples_csv(path)
    for name in ('pressure', 'displacement', 'force', 'probe_distance', 'spring_offset'):
        np.testing.assert_array_equal(getattr(back, name), getattr(samples, name))


def test_samples_csv_accepts_reordered_columns_and_blank_lines(tmp_path):
    path = tmp_path / 'samples.csv'
    path.write_text('force_n,pressure_pa,displacement_m,spring_offset_m,probe_distance_m\n'
                    '2.0,10000,0.004,0.03,0.5\n\n3.0,10000,0.006,0.03,0.5\n')
    samples = read_samples_csv(path)
    np.testing.assert_array_equal(samples.force, [2.0, 3.0])
    np.testing.assert_array_equal(samples.probe_distance, [0.5, 0.5])


GOOD = '10000,0.004,2.0,0.5,0.03\n'


@pytest.mark.parametrize(('text', 'match'), [
    ('', r':1: empty file'),
    ('pressure,displacement,force\n' + GOOD, r':1: expected the header'),
    (','.join(SAMPLES_HEADER) + '\n', r':1: no data rows'),
    (','.join(SAMPLES_HEADER) + '\n' + GOOD + '10000,0.004,abc,0.5,0.03\n',
     r":3: column 'force_n': expected a finite number, got 'abc'"),
    (','.join(SAMPLES_HEADER) + '\n' + GOOD + '10000,nan,2.0,0.5,0.03\n',
     r":3: column 'displacement_m': expected a finite number"),
    (','.join(SAMPLES_HEADER) + '\n' + GOOD + '10000,0.004,2.0\n', r':3: expected 5 fields'),
    (','.join(SAMPLES_HEADER) + '\n' + '-5,0.004,2.0,0.5,0.03\n',
     r":2: column 'pressure_pa': must be positive"),
    (','.join(SAMPLES_HEADER) + '\n' + '10000,0.004,2.0,0.02,0.03\n',
     r":2: column 'probe_distance_m': must exceed spring_offset_m"),
    (','.join(SAMPLES_HEADER) + '\n' + '10000,0.004,2.0,0.5,-0.03\n',
     r":2: column 'spring_offset_m': must be non-negative"),
])
def test_samples_csv_errors_name_file_line_and_column(tmp_path, text, match):
    path = tmp_path / 'bad.csv'
    path.write_text(text)
    with pytest.raises(SamplesFormatError, match='bad.csv' + match):
        read_samples_csv(path)


@pytest.mark.parametrize(('columns', 'match'), [
    (([1e4, 2e4], [0.1], [1.0, 1.0], [0.5, 0.5], [0.03, 0.03]), 'expected displacement'),
    (([1e4, np.nan], [0.1, 0.1], [1.0, 1.0], [0.5, 0.5], [0.03, 0.03]), 'pressure must be fin'),
    (([1e4, 0.0], [0.1, 0.1], [1.0, 1.0], [0.5, 0.5], [0.03, 0.03]), 'pressure must be pos'),
    (([[1e4]], [[0.1]], [[1.0]], [[0.5]], [[0.03]]), r'expected pressure of shape \(n,\)'),
    (([1e4], [0.1], [1.0], [0.02], [0.03]), 'probe_distance must be greater'),
])
def test_cantilever_samples_validate_shapes_and_ranges(columns, match):
    with pytest.raises(ValueError, match=match):
        CantileverSamples(*columns)


def test_synthetic_samples_reject_bad_arguments():
    with pytest.raises(ValueError, match='rng'):
        synthetic_samples(7)
    with pytest.raises(ValueError, match='n_linear'):
        synthetic_samples(np.random.default_rng(7), n_linear=1)
    with pytest.raises(ValueError, match='spring_offset < probe_distance'):
        synthetic_samples(np.random.default_rng(7), probe_distance=0.02)


# --- CLI -----------------------------------------------------------------------------------------

def test_cli_synthetic_writes_samples_and_parseable_outputs(tmp_path, capsys):
    samples_path, out = tmp_path / 'samples.csv', tmp_path / 'out'
    assert main([str(samples_path), '--out', str(out), '--synthetic', '--seed', '7']) == 0
    assert len(read_samples_csv(samples_path)) == len(synthetic_samples(np.random.default_rng(7)))
    rows = list(csv.DictReader((out / 'table3.csv').read_text().splitlines()))
    assert [float(r['pressure_pa']) for r in rows] == [row.pressure for row in TABLE3]
    for r, row in zip(rows, TABLE3, strict=True):
        assert abs(float(r['stiffness_nm_per_rad']) - row.stiffness) <= 2.0 * row.stiffness_std
    markdown = (out / 'table3.md').read_text().splitlines()
    assert markdown[0].startswith('| p [kPa] |') and len(markdown) == 2 + len(TABLE3)
    assert (out / 'fig9.png').read_bytes()[:8] == PNG_MAGIC
    assert 'table3.csv' in capsys.readouterr().out


def test_cli_reads_a_samples_file_and_refuses_to_overwrite_it(tmp_path, capsys):
    samples_path, out = tmp_path / 'samples.csv', tmp_path / 'out'
    write_samples_csv(samples_path, synthetic_samples(np.random.default_rng(7), n_linear=5,
                                                      n_saturated=2))
    before = samples_path.read_bytes()
    assert main([str(samples_path), '--out', str(out)]) == 0
    assert len(list(csv.DictReader((out / 'table3.csv').open()))) == len(TABLE3)
    assert main([str(samples_path), '--out', str(out), '--synthetic']) == 1
    assert samples_path.read_bytes() == before
    assert 'will not overwrite' in capsys.readouterr().err


def test_cli_reports_bad_input_with_non_zero_exit(tmp_path, capsys):
    bad = tmp_path / 'bad.csv'
    bad.write_text(','.join(SAMPLES_HEADER) + '\n10000,0.004,oops,0.5,0.03\n')
    out = tmp_path / 'out'
    assert main([str(bad), '--out', str(out)]) == 1
    err = capsys.readouterr().err
    assert "bad.csv:2: column 'force_n'" in err and not out.exists()
    assert main([str(tmp_path / 'missing.csv'), '--out', str(out)]) == 1
    assert 'missing.csv' in capsys.readouterr().err
    assert main([str(bad), '--out', str(out), '--seed', '3']) == 2
    assert main([str(bad)]) == 2
    assert main([str(bad), '--out', str(out), '--radius', '-1']) == 2
