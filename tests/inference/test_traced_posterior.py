"""The posterior numpyro sees, built from an abstract trace of the model
(:func:`bayes_roadload.inference.nuts.unconstrained_posterior`)."""

import numpy as np
import pytest


@pytest.mark.slow  # a second numerical check of the potential every fit samples, ~15 s
@pytest.mark.parametrize("pooling", ["pooled", "hierarchical"])
def test_traced_posterior_equals_numpyro_initialisation(small_campaign, pooling):
    """unconstrained_posterior's abstract trace gives numpyro's own starting point, potential
    and gradient there (initialize_model), and the same constrained values back."""
    import jax
    from jax.flatten_util import ravel_pytree
    from numpyro.infer.util import init_to_value, initialize_model

    from bayes_roadload.inference.bayes import build_problem
    from bayes_roadload.inference.nuts import _traced_potential, prepare_problem

    problem, init = prepare_problem(build_problem(small_campaign, "four_term", pooling=pooling), small_campaign)
    traced = _traced_potential(problem, init)
    assert traced is not None  # the path a fit takes
    z0, potential, postprocess = traced
    info, ref_potential, ref_postprocess, _ = initialize_model(
        jax.random.PRNGKey(0), problem.numpyro_model, model_args=(problem,),
        init_strategy=init_to_value(values=init), validate_grad=False)
    assert sorted(z0) == sorted(info.z)
    a, b = ravel_pytree(z0)[0], ravel_pytree(info.z)[0]
    np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-12, atol=1e-12)
    # compiled, as the sampler runs them (op by op, each took several seconds)
    value, grad = jax.jit(jax.value_and_grad(potential))(z0)
    ref_value, ref_grad = jax.jit(jax.value_and_grad(ref_potential))(info.z)
    assert float(value) == pytest.approx(float(ref_value), rel=1e-12)
    np.testing.assert_allclose(np.asarray(ravel_pytree(grad)[0]), np.asarray(ravel_pytree(ref_grad)[0]),
                               rtol=1e-9, atol=1e-9)
    back, ref_back = postprocess(z0), ref_postprocess(info.z)
    for k in ("AD", "CD0", "v0_mps"):
        np.testing.assert_allclose(np.asarray(back[k]), np.asarray(ref_back[k]), rtol=1e-12)
    # a latent site without a start value is left to numpyro's initialisation
    assert _traced_potential(problem, {k: v for k, v in init.items() if k != "AD"}) is None
