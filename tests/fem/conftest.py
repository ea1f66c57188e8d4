import pytest
from fem_helpers import make_continuum


@pytest.fixture(params=["neo-hookean", "svk"])
def continuum(request):
    return make_continuum(request.param)
