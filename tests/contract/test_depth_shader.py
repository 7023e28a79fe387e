"""The depth cameras' shader (sim/shaders/, sim/renderer.py): SAPIEN's default shader without
image-based lighting renders the pictures the pipeline reads bit for bit as the default one,
and it is what every world's camera renders with."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import sapien

from clutterbench.sim.config import CameraConfig
from clutterbench.sim.pull import SceneState, world_at
from clutterbench.sim.render import render_depth_instance
from clutterbench.sim.renderer import DEPTH_SHADER_DIR, add_depth_camera
from clutterbench.trials.ch6.episodes import job_spec
from clutterbench.trials.config import SceneStreamConfig
from tests.toy_jobs import toy_ch6_jobs

READ = ("Position", "Segmentation", "GbufferDepth")
"""The pictures the pipeline reads (sim/render.py, sim/pile.py)."""
STREAM = SceneStreamConfig(families={"shelved": 1, "stacked": 1, "random": 3}, n_objects=(3, 10))


def test_the_shader_differs_from_sapiens_default_only_in_its_lighting():
    default = Path(sapien.__file__).parent / "vulkan_shader" / "default"
    ours = sorted(p.name for p in DEPTH_SHADER_DIR.iterdir())
    assert ours == sorted(p.name for p in default.iterdir())
    changed = [n for n in ours if (DEPTH_SHADER_DIR / n).read_text() != (default / n).read_text()]
    assert changed == ["deferred.frag", "gbuffer1.frag", "scene_set.glsl"]
    for name in changed:
        assert "clutterbench" in (DEPTH_SHADER_DIR / name).read_text()  # marked as changed


@pytest.mark.parametrize("size", [64, 128, 256])
def test_position_and_ids_are_the_default_shaders_bit_for_bit(physics, size):
    """Scenes of ch. 6's 3-10 box families, each seen by the world's own camera and by a camera
    with SAPIEN's default shader at the same pose."""
    for job in toy_ch6_jobs("oracle", STREAM, CameraConfig(image_size=size), episodes=3):
        spec = job_spec(job)
        world = world_at(spec, SceneState.start(spec), physics, render=True)
        render_depth_instance(world, job.camera)
        ours = world.camera
        assert sapien.render.get_camera_shader_dir() != str(DEPTH_SHADER_DIR)  # put back
        fovy = np.deg2rad(job.camera.fovy_deg)
        default = world.scene.add_camera(
            "default", size, size, fovy, job.camera.near_m, job.camera.far_m
        )
        default.entity.set_pose(ours.entity.get_pose())
        world.scene.update_render()
        ours.take_picture()
        default.take_picture()
        assert "Lighting" in default.get_picture_names()
        for name in READ:
            a, b = ours.get_picture(name), default.get_picture(name)
            assert a.dtype == b.dtype and a.tobytes() == b.tobytes(), (spec.family, name)


def test_a_depth_camera_puts_the_process_shader_back():
    scene = sapien.Scene()
    before = sapien.render.get_camera_shader_dir()
    add_depth_camera(scene, "c", 8, 1.0, 0.01, 10.0)
    assert sapien.render.get_camera_shader_dir() == before
