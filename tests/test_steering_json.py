"""Model files: exact JSON round trip and clear errors for bad files."""

import json
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hasa_env.steering import GeneralizedModel, ModelFileError, SteeringModel, TwoPointModel
from hasa_env.steering.base import MODEL_TYPES, Design, Regressor, lagged

any_float = st.floats(allow_nan=False, allow_infinity=False)
positive = st.floats(1e-6, 1e6, allow_nan=False)


@st.composite
def models(draw):
    common = {
        "near_distance": draw(positive),
        "far_distance": draw(positive),
        "dt": draw(positive),
        "decision_lag": draw(st.integers(0, 3)),
        "name": draw(st.text(max_size=20)),
    }
    if draw(st.booleans()):
        orders = [draw(st.integers(0, 5)) for _ in range(4)]
        size = sum(orders)
        model = GeneralizedModel(*orders, **common)
    else:
        size = 3
        model = TwoPointModel(**common)
    if draw(st.booleans()):
        params = draw(st.lists(any_float, min_size=size, max_size=size))
        errors = draw(st.none() | st.lists(st.floats(0, 1e300), min_size=size, max_size=size))
        model = model.with_parameters(params, errors)
    return model


@settings(max_examples=150, deadline=None)
@given(model=models())
def test_json_round_trip_is_exact(model):
    text = model.to_json()
    back = SteeringModel.from_json(text)
    assert type(back) is type(model)
    assert back == model
    assert back.to_json() == text
    if model.is_fitted:
        assert np.array_equal(back.parameter_vector, model.parameter_vector)
        assert back.parameters == model.parameters
    assert type(model).from_json(text) == model


def test_save_and_load(tmp_path):
    path = tmp_path / "model.json"
    model = GeneralizedModel.paper()
    model.save(path)
    assert SteeringModel.load(path) == model
    assert GeneralizedModel.load(path) == model
    document = json.loads(path.read_text())
    assert document["type"] == "generalized"
    assert document["features"]["regressors"][0] == "delta(k-1)"
    assert document["parameters"]["a2"] == -0.51


def _with_covariance() -> GeneralizedModel:
    """The paper's preset with a covariance of its parameters, as a fit keeps it."""
    model = GeneralizedModel.paper()
    n = len(model.parameter_names)
    root = np.linspace(1.0, 2.0, n * n).reshape(n, n) * 1e-3
    covariance = root @ root.T
    model = model.with_parameters(model.parameters, np.sqrt(np.diag(covariance)))
    model.saved_covariance = covariance
    return model


def test_the_parameter_covariance_round_trips_exactly(tmp_path):
    path = tmp_path / "model.json"
    model = _with_covariance()
    model.save(path)
    loaded = SteeringModel.load(path)
    np.testing.assert_array_equal(loaded.parameter_covariance, model.parameter_covariance)
    document = json.loads(path.read_text())
    names = list(model.parameter_names)
    assert list(document["parameter_covariance"]) == names
    assert list(document["parameter_covariance"]["a1"]) == names
    assert GeneralizedModel.paper().parameter_covariance is None  # a preset: unknown
    assert "parameter_covariance" not in GeneralizedModel.paper().to_dict()


def _covariance_document():
    return _with_covariance().to_dict()


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (
            lambda d: d["parameter_covariance"].pop("b3"),
            r"'parameter_covariance' must name every parameter in every row .*rows \[",
        ),
        (
            lambda d: d["parameter_covariance"]["a1"].pop("b3"),
            r"'parameter_covariance' must name every parameter in every row .*row 'a1' does not",
        ),
        (
            lambda d: d["parameter_covariance"]["a1"].update(a2=1.0),
            r"'parameter_covariance' is not symmetric",
        ),
        (
            lambda d: d["parameter_covariance"]["a1"].update(a1=-1e-6),
            r"'parameter_covariance' has a negative variance on its diagonal \('a1'",
        ),
        (
            lambda d: d["parameter_covariance"]["a1"].update(a1=1.0),
            r"'parameter_covariance' has a diagonal that is not the squared 'standard_errors'",
        ),
        (
            lambda d: d["parameter_covariance"]["a1"].update(a2="big"),
            r"field 'parameter_covariance.a1.a2' must be a finite number",
        ),
        (
            lambda d: d.update(parameters=None, standard_errors=None),
            r"'parameter_covariance' given without 'parameters'",
        ),
    ],
)
def test_a_bad_parameter_covariance_is_named(tmp_path, change, message):
    _assert_refused(tmp_path, _covariance_document(), change, message)


def _assert_refused(tmp_path, document, change, message):
    """``document`` changed by ``change`` is refused on loading, naming the file and ``message``."""
    change(document)
    path = write(tmp_path, document)
    with pytest.raises(ModelFileError, match=message) as info:
        SteeringModel.load(path)
    assert str(path) in str(info.value)


def write(tmp_path, document, name="bad.json"):
    path = tmp_path / name
    path.write_text(document if isinstance(document, str) else json.dumps(document))
    return path


def good():
    return GeneralizedModel.paper().to_dict()


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (
            lambda d: d.update(format="something"),
            r"field 'format' = 'something' is not allowed: only 'hasa_env.steering_model'",
        ),
        (
            lambda d: d.update(format_version=7),
            r"field 'format_version' = 7 is not allowed: only 1 \(the version this hasa_env reads",
        ),
        (
            lambda d: d.update(type="neural"),
            r"field 'type' = 'neural' is not allowed: one of .*generalized.*two_point.* \(a custom",
        ),
        (lambda d: d.pop("parameters"), r"field 'parameters' is missing"),
        (
            lambda d: d.update(colour="red"),
            r"unknown field 'colour' \(allowed keys here: class, dt, equation_error, features",
        ),
        (lambda d: d.update(dt=-0.01), r"field 'dt' must be a finite positive number, got -0.01"),
        (lambda d: d.update(dt="fast"), r"field 'dt' must be a finite positive number"),
        (lambda d: d["features"].update(near_distance=0), r"field 'features.near_distance'"),
        (
            lambda d: d["features"].update(decision_lag=1.5),
            r"'features.decision_lag' must be a non-neg",
        ),
        (lambda d: d["features"].update(eyes=2), r"unknown field 'features.eyes'"),
        (lambda d: d["structure"].update(nb=-2), r"field 'structure' is not valid .*order nb"),
        (lambda d: d["structure"].update(ne=1), r"field 'structure' is not valid"),
        (
            lambda d: d["parameters"].pop("b3"),
            r"field 'parameters' has missing \['b3'\].*allowed names",
        ),
        (lambda d: d["parameters"].update(b9=1.0), r"field 'parameters' has unexpected \['b9'\]"),
        (
            lambda d: d["parameters"].update(b0="big"),
            r"field 'parameters.b0' must be a finite number",
        ),
        (
            lambda d: d["parameters"].update(b0=float("nan")),
            r"'parameters.b0' must be a finite number",
        ),
        (
            lambda d: d.update(standard_errors={k: -1.0 for k in d["parameters"]}),
            r"'standard_errors.a1' must be a finite non-negative number, got -1.0",
        ),
        (lambda d: d["features"].update(regressors=["phi(k)"]), r"field 'features.regressors'"),
        (lambda d: d.update(name=3), r"field 'name' must be a string"),
    ],
)
def test_bad_model_files_give_clear_errors(tmp_path, change, message):
    _assert_refused(tmp_path, good(), change, message)


def test_unreadable_files(tmp_path):
    with pytest.raises(ModelFileError, match=r"not valid JSON \(line 1, column"):
        SteeringModel.load(write(tmp_path, "{not json"))
    with pytest.raises(
        ModelFileError, match=r"the document must be a mapping \(JSON object\), got \[1, 2\]"
    ):
        SteeringModel.load(write(tmp_path, "[1, 2]"))
    with pytest.raises(ModelFileError, match="no such model file"):
        SteeringModel.load(tmp_path / "missing.json")
    binary = tmp_path / "binary.json"
    binary.write_bytes(b"\xff\xfe\x00")
    with pytest.raises(ModelFileError, match="not a UTF-8 text file"):
        SteeringModel.load(binary)
    path = write(tmp_path, GeneralizedModel.paper().to_json())
    with pytest.raises(ModelFileError, match="TwoPointModel.from_json expects 'two_point'"):
        TwoPointModel.load(path)


class NearPointPD(SteeringModel):
    """A user's model, defined outside the library (as in examples/custom_steering_model.py)."""

    model_type = "test_near_point_pd"

    @property
    def parameter_names(self):
        return ("memory", "proportional", "derivative")

    @property
    def regressors(self):
        return (Regressor("delta", 1), Regressor("phi", 0), Regressor("phi", 1))

    def design(self, features):
        delta = features["delta"].to_numpy()
        phi = features["phi"].to_numpy()
        matrix = np.column_stack([lagged(delta, 1), phi, phi - lagged(phi, 1)])
        return Design(delta, np.zeros_like(delta), matrix)


def test_a_custom_model_registers_and_round_trips(tmp_path):
    assert MODEL_TYPES["test_near_point_pd"] is NearPointPD
    model = NearPointPD([0.9, 0.1, 0.5], name="mine")
    path = tmp_path / "mine.json"
    model.save(path)
    assert SteeringModel.load(path) == model
    assert model.arx() is None


def test_a_model_type_cannot_be_taken_twice():
    with pytest.raises(TypeError, match="already used"):

        class Impostor(NearPointPD):
            model_type = "generalized"

    with pytest.raises(TypeError, match="must set the class attribute model_type"):

        class Nameless(NearPointPD):
            model_type = ""


@pytest.mark.slow
def test_the_custom_model_example_runs(capsys):
    import runpy
    from pathlib import Path

    example = Path(__file__).resolve().parents[1] / "examples" / "custom_steering_model.py"
    runpy.run_path(str(example), run_name="__main__")
    out = capsys.readouterr().out
    assert "saved and loaded near_far_pd.json" in out and "identical model" in out
    assert "left the road: False" in out


def _fresh_process(code: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=False, timeout=120
    )


def test_load_in_a_fresh_process_that_imported_only_steering_model(tmp_path) -> None:
    """The README's ``from hasa_env.steering import SteeringModel``, then
    ``SteeringModel.load(path)``, reads a built-in model's file in a process that imported
    nothing else (the built-in types used to be unregistered there, and reading failed with an
    internal error about an empty 'choice' field)."""
    path = tmp_path / "model.json"
    GeneralizedModel.paper().save(path)
    out = _fresh_process(
        "from hasa_env.steering import SteeringModel\n"
        f"print(type(SteeringModel.load({str(path)!r})).__name__)\n"
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "GeneralizedModel"


def test_load_before_any_type_is_defined_says_what_to_import(tmp_path) -> None:
    """Only hasa_env.steering.base imported: no type is registered yet, and the error says so
    (a ModelFileError naming the file), not an internal one."""
    path = tmp_path / "model.json"
    GeneralizedModel.paper().save(path)
    out = _fresh_process(
        "from hasa_env.steering.base import SteeringModel\n"
        "from hasa_env.steering.model_file import ModelFileError\n"
        "try:\n"
        f"    SteeringModel.load({str(path)!r})\n"
        "except ModelFileError as exc:\n"
        "    print(exc)\n"
    )
    assert out.returncode == 0, out.stderr
    assert f"{path}: no steering model type is defined yet: import hasa_env.steering" in out.stdout
