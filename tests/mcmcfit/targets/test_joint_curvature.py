"""Joint coordinates and curvature: one image is the single fit; gradients; the joint mode and Laplace.

Two renders of one small synthetic face (``face_factory``, 56x56, other yaw and
light), each with landmarks and a region likelihood. Checked against
independent truth: the single-image coordinates and curvature (one image),
central differences of the exact joint log density (the sampler's ray-cast
likelihoods, the identity's prior once, the log-Jacobian), and the
information the second photograph adds (the joint Laplace sds of the albedo
below either image's own).
"""

from __future__ import annotations

import numpy as np
import pytest
from face_factory import scene, small_face_model, synthetic_target

from albedo_model.params import ImageSize, MoMoCoefficients, SHLight
from albedo_model.render.region import contour_jump, interior_region
from albedo_model.render.renderer import Renderer
from albedo_model.scene_vector import SceneLayout
from mcmcfit.fitting.mode import find_mode, laplace
from mcmcfit.sampling.kernel import init
from mcmcfit.targets.curvature import PosteriorCurvature
from mcmcfit.targets.face import FaceTarget
from mcmcfit.targets.image import ImageLikelihood, prepare_image_target
from mcmcfit.targets.joint import JointTarget
from mcmcfit.targets.joint_curvature import JointCurvature, joint_coordinate_gradient
from mcmcfit.targets.landmarks import LandmarkGeometry, LandmarkTarget
from mcmcfit.targets.priors import LogPrior
from proposals.joint import JointParameter
from proposals.laplace.coordinates import SamplingCoordinates
from proposals.laplace.joint_coordinates import JointCoordinates

SIZE = 56
SIGMA = 0.03


@pytest.fixture(scope="module")
def problem():
    model = small_face_model(subdivisions=4)
    rng = np.random.default_rng(5)
    identity = MoMoCoefficients(rng.normal(size=4), rng.normal(size=3), np.zeros(2))
    faces, truths, curvatures, coords = [], [], [], []
    for k, yaw in enumerate((0.3, -0.25)):
        truth = scene(SIZE, SIZE, yaw=yaw, pitch=-0.05, coefficients=identity._replace(
            expression=rng.normal(0, 0.7, 2)))
        truth = truth._replace(environment_map=SHLight(
            SHLight.frontal(0.7 + 0.2 * k, 0.4 * (-1) ** k).coefficients
            + rng.normal(0, 0.03, (9, 3))))
        image, clicked = synthetic_target(model, truth, specular=False)
        image = np.clip(image + rng.normal(0, 0.01, image.shape), 0, 1)
        renderer = Renderer(model, specular=False, threads=1)
        base = renderer.render(truth)
        region = interior_region(base.state.prim_id, base.state.hits.t, SIZE, SIZE, erode=2,
                                 jump=contour_jump(7.5 / 2.0 * SIZE))
        lm = LandmarkTarget(LandmarkGeometry(model, threads=1), clicked, sigma=2.0,
                            image_size=ImageSize(SIZE, SIZE))
        lik = ImageLikelihood(prepare_image_target(image), sigma=SIGMA, region=region)
        face = FaceTarget(renderer, lik, lm, LogPrior())
        lay = SceneLayout.for_params(truth)
        faces.append(face)
        truths.append(truth)
        curvatures.append(PosteriorCurvature(face, lay))
        coords.append(SamplingCoordinates(lay, truth))
    return model, identity, truths, faces, curvatures, coords


def _joint(problem):
    _, _, truths, faces, curvatures, coords = problem
    return (JointTarget(faces, LogPrior()), JointCurvature(curvatures),
            JointCoordinates(coords), JointParameter.share(truths))


def _exact(target, coords, params):
    return init(params, target).log_posterior + coords.log_jacobian(coords.u_of(params))


def test_one_image_is_the_single_fit(problem):
    _, _, truths, faces, curvatures, coords = problem
    jc = JointCoordinates(coords[:1])
    jp = JointParameter((truths[0],))
    u = coords[0].u_of(truths[0])
    idx = jc.index[0]  # the joint order: the identity first, then the image's own
    assert sorted(idx) == list(range(jc.size))
    np.testing.assert_array_equal(jc.u_of(jp)[idx], u)
    assert [jc.names[j] for j in idx] == [n if n.startswith(("shape.", "albedo.")) else
                                          f"image0.{n}" for n in coords[0].names]
    assert jc.log_jacobian(jc.u_of(jp)) == coords[0].log_jacobian(u)
    cur = curvatures[0].at(truths[0])
    g1, p1 = coords[0].to_coordinates(cur.gradient, cur.precision, u,
                                      second_order=cur.exact_gradient)
    jcur = JointCurvature(curvatures[:1]).at(jp)
    g, p = jc.to_coordinates(jcur.gradient, jcur.precision, jc.u_of(jp),
                             second_order=jcur.exact_gradient)
    np.testing.assert_allclose(g[idx], g1, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(p[np.ix_(idx, idx)], p1, rtol=1e-12, atol=1e-9)
    moved = jc.u_of(jp) + 0.01
    assert jc.params_of(moved, jp).images[0].pose == coords[0].params_of(moved[idx],
                                                                         truths[0]).pose


def test_params_of_keeps_unchanged_images_and_one_identity(problem):
    target, _, jc, jp = _joint(problem)
    u = jc.u_of(jp)
    assert jc.params_of(u, jp) is jp
    own = u.copy()
    own[jc.names.index("image1.angles.0")] += 0.01
    moved = jc.params_of(own, jp)
    assert moved.images[0] is jp.images[0] and moved.images[1] is not jp.images[1]
    assert moved.images[1].momo.shape is jp.images[0].momo.shape
    shared = u.copy()
    shared[jc.names.index("albedo.1")] += 0.1
    moved = jc.params_of(shared, jp)
    assert moved.images[0].momo.albedo is moved.images[1].momo.albedo
    assert moved.images[0].momo.albedo[1] == pytest.approx(jp.images[0].momo.albedo[1] + 0.1)
    np.testing.assert_allclose(jc.u_of(moved), shared, atol=1e-9)
    assert jc.image_of(np.array(jc.names) == "image1.angles.0") == {1}
    assert jc.image_of(np.array(jc.names) == "shape.0") == {0, 1}


def test_joint_gradient_is_the_exact_densitys(problem):
    """The joint gradient in u (Gauss-Newton curvature's, and the HMC path's) vs central differences."""
    target, cur, jc, jp = _joint(problem)
    p = jc.params_of(jc.u_of(jp) + 0.02 * np.random.default_rng(3).normal(size=jc.size), jp)
    u = jc.u_of(p)
    parts = cur.at(p)
    g, prec = jc.to_coordinates(parts.gradient, parts.precision, u,
                                second_order=parts.exact_gradient)
    _, g_hmc = joint_coordinate_gradient(cur, jc)(p)
    np.testing.assert_allclose(g_hmc, g, rtol=0, atol=2e-3 * np.abs(g).max())
    assert np.all(np.linalg.eigvalsh(0.5 * (prec + prec.T)) > -1e-6 * np.abs(prec).max())
    rng = np.random.default_rng(4)
    for _ in range(4):  # directional derivatives along random small directions
        d = 1e-3 * rng.normal(size=jc.size)
        fd = (_exact(target, jc, jc.params_of(u + d, p))
              - _exact(target, jc, jc.params_of(u - d, p))) / 2
        assert g @ d == pytest.approx(fd, rel=0.05, abs=0.05)


def test_joint_mode_and_laplace_add_the_second_photographs_information(problem):
    model, identity, truths, faces, curvatures, coords = problem
    target, cur, jc, jp = _joint(problem)
    start = JointParameter.share([t._replace(momo=t.momo._replace(
        shape=np.zeros(4), albedo=np.zeros(3))) for t in truths])
    res = find_mode(target, cur, jc, start, rng=np.random.default_rng(0), max_steps=20)
    assert res.iterations >= 2 and all(b >= a for a, b in zip(res.trace, res.trace[1:]))
    assert res.log_density > _exact(target, jc, jp) - 5.0  # at least as good as the truth
    assert res.params.images[0].momo.albedo is res.params.images[1].momo.albedo
    joint = laplace(cur, jc, res.params)
    albedo = [jc.names.index(f"albedo.{k}") for k in range(3)]
    sd_joint = np.sqrt(np.diag(np.linalg.inv(joint.precision))[albedo])
    for i in range(2):  # each photograph alone, at the joint mode
        single = laplace(curvatures[i], coords[i], res.params.images[i])
        idx = [coords[i].names.index(f"albedo.{k}") for k in range(3)]
        sd_single = np.sqrt(np.diag(np.linalg.inv(single.precision))[idx])
        assert np.all(sd_joint < sd_single)
    # the joint mode's albedo is within a few joint sds of the truth
    err = (np.asarray(res.params.images[0].momo.albedo) - identity.albedo) / sd_joint
    assert np.all(np.abs(err) < 5.0)
