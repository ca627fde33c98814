"""Small scene builders shared by the Virtual Pipeline tests."""

from glassdist.scene import scene_from_dict


def make_scene(*, yaw=0.0, pitch=0.0, deformation=None, pixels=(64, 48), camera_z=-3000.0, pane_size=(2000, 2000),
               frame=None, backdrop=None, camera=None, **extra):
    pane = dict(size_mm=list(pane_size), thickness_mm=20, refractive_index=1.52, yaw_deg=yaw, pitch_deg=pitch,
                deformation=deformation or {})
    if frame is not None:
        pane["frame"] = frame
    bd = dict(pattern="lines", pitch_mm=24.2, line_width_mm=4, distance_m=10)
    bd.update(backdrop or {})
    cam = dict(focal_length_mm=300, sensor_width_mm=36, pixels=list(pixels), position_mm=[0, 0, camera_z])
    cam.update(camera or {})
    return scene_from_dict(dict(pane=pane, backdrop=bd, camera=cam, **extra))
