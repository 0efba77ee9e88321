"""Tag textures, detection (ids, families, corner convention) and the pose from a tag."""
import numpy as np
import pytest

from frog_vision.core.detection import DetectorSettings, TagDetector
from frog_vision.core.pose import PoseSettings, TagPoseEstimator, compose_offset, invert_pose
from frog_vision.core.renderer import RenderSettings, TankRenderer
from frog_vision.core.tag_images import tag_border_cells, tag_image, tag_total_size


@pytest.mark.parametrize("family,tag_id", [("tagStandard41h12", 47), ("tag36h11", 3), ("tag25h9", 2)])
def test_tag_images_decode_as_their_id(family, tag_id):
    import cv2
    img = cv2.resize(tag_image(family, tag_id), None, fx=12, fy=12, interpolation=cv2.INTER_NEAREST)
    canvas = np.full((300, 300), 255, np.uint8)
    canvas[60:60 + img.shape[0], 60:60 + img.shape[1]] = img
    dets = TagDetector(DetectorSettings(family=family, tag_ids=())).detect(canvas)
    assert [d.tag_id for d in dets] == [tag_id]
    # the detected square is width_at_border cells, with OpenCV pixel centres
    n, b = tag_image(family, tag_id).shape[0], tag_border_cells(family)
    lo = 60 + (n - b) / 2 * 12 - 0.5
    assert np.allclose(np.sort(dets[0].corners[:, 0])[[0, -1]], [lo, lo + b * 12], atol=0.6)
    assert tag_total_size("tagStandard41h12", 0.047) == pytest.approx(0.047 * 9 / 5)


def test_bad_family_or_id():
    with pytest.raises(ValueError, match="not one of"):
        tag_image("tag99h1", 0)
    with pytest.raises(ValueError, match="out of range"):
        tag_image("tag36h11", 100000)


def test_rendered_corners_match_ground_truth(clean_renderer):
    pose = np.array([0.05, -0.1, 0.7])
    img = clean_renderer.render(pose)
    dets = TagDetector().detect(img)
    assert len(dets) == 1 and dets[0].tag_id == 47
    truth = clean_renderer.project_tag_corners(pose)
    assert np.max(np.linalg.norm(dets[0].corners - truth, axis=1)) < 0.15


def test_pose_from_tag_at_many_poses(clean_renderer, camera, camera_pose, rng):
    est = TagPoseEstimator(camera, camera_pose, PoseSettings())
    det = TagDetector()
    errs, herrs = [], []
    for _ in range(15):
        pose = np.array([rng.uniform(-0.15, 0.15), rng.uniform(-0.25, 0.25), rng.uniform(-np.pi, np.pi)])
        d = det.detect(clean_renderer.render(pose))
        m, why = est.measure(d[0])
        assert why is None
        errs.append(np.linalg.norm(m.pose[:2] - pose[:2]))
        herrs.append(abs(np.angle(np.exp(1j * (m.pose[2] - pose[2])))))
        # the stated covariance is of the right size: errors within ~4 sigma
        assert errs[-1] < 4 * np.sqrt(np.trace(m.covariance[:2, :2])) + 1e-4
    assert np.mean(errs) < 0.2e-3 and np.degrees(np.mean(herrs)) < 0.1


def test_tag_to_body_offset(camera, camera_pose):
    offset = (-0.01, 0.004, 0.1)            # body frame in the tag frame
    r = TankRenderer(camera, camera_pose, RenderSettings(noise_sigma=1.0, exposure=0.0))
    body = np.array([0.02, 0.05, -1.0])
    # tag pose in the body frame is the inverse of the offset
    img = r.render(body, tag_offset=tuple(invert_pose(offset)))
    est = TagPoseEstimator(camera, camera_pose, PoseSettings(offset_x=offset[0], offset_y=offset[1],
                                                             offset_yaw=offset[2]))
    m, _ = est.measure(TagDetector().detect(img)[0])
    assert np.allclose(m.pose[:2], body[:2], atol=2e-4)
    assert np.angle(np.exp(1j * (m.pose[2] - body[2]))) == pytest.approx(0, abs=5e-3)
    back, _ = compose_offset(compose_offset(body, invert_pose(offset))[0], offset)
    assert np.allclose(back, body)


def test_other_tags_and_ids_are_ignored(camera, camera_pose):
    # a second robot with another id of the same family, and the board's tag36h11 tags
    a = TankRenderer(camera, camera_pose, RenderSettings(noise_sigma=1.0, exposure=0.0))
    b = TankRenderer(camera, camera_pose, RenderSettings(noise_sigma=1.0, exposure=0.0, tag_id=12))
    img_a = a.render(np.array([0.0, -0.15, 0.3]))
    img_b = b.render(np.array([0.0, 0.15, -0.3]))
    img = img_a.copy()
    img[:, 320:] = img_b[:, 320:]
    dets = TagDetector().detect(img)
    assert [d.tag_id for d in dets] == [47]
    assert TagDetector(DetectorSettings(tag_ids=())).detect(img).__len__() == 2


def test_tag_half_out_of_view_is_rejected(clean_renderer, camera, camera_pose):
    est = TagPoseEstimator(camera, camera_pose)
    # image right edge is tank y = +0.416 at x = 0: put the tag centre right at the edge
    img = clean_renderer.render(np.array([0.0, 0.405, 0.0]))
    for d in TagDetector().detect(img):
        m, why = est.measure(d)
        assert m is None and "border" in why


def test_bad_images():
    det = TagDetector()
    with pytest.raises(ValueError, match="dtype"):
        det.detect(np.zeros((10, 10), np.float32))
    with pytest.raises(ValueError, match="shape"):
        det.detect(np.zeros((10, 10, 4), np.uint8))


def test_lens_distortion_is_rendered_as_the_camera_model_undoes_it(camera_pose, rng):
    from frog_vision.core.camera_model import CameraModel
    cam = CameraModel(640, 480, [[612.0, 0.0, 322.0], [0.0, 611.0, 236.0], [0.0, 0.0, 1.0]],
                      [-0.15, 0.06, 0.0005, -0.0008, 0.0])
    r = TankRenderer(cam, camera_pose, RenderSettings(noise_sigma=1.0, exposure=0.0))
    est = TagPoseEstimator(cam, camera_pose)
    naive = TagPoseEstimator(CameraModel(640, 480, cam.K), camera_pose)
    pose = np.array([0.12, 0.3, 0.4])                 # near a corner: distortion is largest
    d = TagDetector().detect(r.render(pose))[0]
    assert np.max(np.linalg.norm(d.corners - r.project_tag_corners(pose), axis=1)) < 0.2
    m, _ = est.measure(d)
    assert np.linalg.norm(m.pose[:2] - pose[:2]) < 3e-4
    # ignoring the distortion would be millimetres off
    assert np.linalg.norm(naive.measure(d)[0].pose[:2] - pose[:2]) > 2e-3
