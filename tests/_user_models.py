"""The source of a user's steering model for the tests that write one to a file and import it
(as a user's module would be): a near/far-point PD controller, written once."""

from __future__ import annotations

NEAR_FAR_PD_BODY = """
    @property
    def parameter_names(self):
        return ("memory", "proportional", "derivative", "far")

    @property
    def regressors(self):
        return (Regressor("delta", 1), Regressor("phi", 0), Regressor("phi", 1),
                Regressor("omega", 0))

    def design(self, features):
        delta = features["delta"].to_numpy(dtype=float)
        phi = features["phi"].to_numpy(dtype=float)
        omega = features["omega"].to_numpy(dtype=float)
        matrix = np.column_stack([lagged(delta, 1), phi, phi - lagged(phi, 1), omega])
        return Design(target=delta, offset=np.zeros_like(delta), matrix=matrix)

    def arx(self):
        if not self.is_fitted:
            return None
        m, k_p, k_d, k_f = self.parameter_vector.tolist()
        return ARXForm(a=(m,), b=(k_p + k_d, -k_d), c=(k_f,), near_distance=self.near_distance,
                       far_distance=self.far_distance, dt=self.dt)
"""


def near_far_pd_module(docstring: str, model_type: str, default_name: str | None = None) -> str:
    """A module's source defining ``NearFarPD`` (model type ``model_type``; ``default_name``:
    the name its instances get unless given one) after the module ``docstring``::

        delta(k) = m delta(k-1) + k_p phi(k) + k_d [phi(k) - phi(k-1)] + k_f Omega(k)
    """
    init = ""
    if default_name is not None:
        init = (
            "\n    def __init__(self, **kwargs):\n"
            f'        kwargs.setdefault("name", "{default_name}")\n'
            "        super().__init__(**kwargs)\n"
        )
    return (
        f'\n"""{docstring}"""\n'
        "import numpy as np\n\n"
        "from hasa_env.steering import ARXForm, Design, Regressor, SteeringModel, lagged\n\n\n"
        "class NearFarPD(SteeringModel):\n"
        '    """delta(k) = m delta(k-1) + k_p phi(k) + k_d [phi(k) - phi(k-1)] + k_f Omega(k)."""\n\n'
        f'    model_type = "{model_type}"\n'
        f"{init}"
        f"{NEAR_FAR_PD_BODY}"
    )
