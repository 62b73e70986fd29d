"""Shared fixtures: the default parameters and the analytic reference model."""

import pytest

from twin.parameters import Parameters
from twin.reference import ReferenceModel


@pytest.fixture(scope="session")
def params() -> Parameters:
    return Parameters()


@pytest.fixture(scope="session")
def reference(params: Parameters) -> ReferenceModel:
    return ReferenceModel(params)
