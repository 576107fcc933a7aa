"""The camera's renderer against independent references: a trimesh + Embree ray caster (depth and
coverage), a plate's analytic depth, OpenCV's projectPoints (the pixel of a 3D point), ERFA-free
Sun geometry (the Astronomical Almanac's low-precision Sun), and itself (bit for bit)."""

from __future__ import annotations

import numpy as np
import pytest

from components.camera.render import egl_problem
from tests.conftest import needs

pytestmark = pytest.mark.skipif(egl_problem() is not None, reason=f"no EGL here: {egl_problem()}")

# an off-centre principal point (and unequal focal lengths): half a pixel or a swapped axis shows
W, H = 320, 240
K = np.array([[300.0, 0.0, 141.3], [0.0, 310.0, 131.8], [0.0, 0.0, 1.0]])


def renderer(K=K, width=W, height=H):
    from components.camera.render import Renderer

    return Renderer(K, width, height, 0.05, 100.0, ambient=0.1)


def rigid(rotvec, translation):
    from scipy.spatial.transform import Rotation

    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    T[:3, 3] = translation
    return T


def scene():
    """A box, a sphere and a cylinder, turned and placed 1.5 to 3 m in front of the camera
    (camera frame = world here), partly covering one another and the image's edges."""
    import trimesh

    return [
        (trimesh.creation.box(extents=(0.8, 0.5, 0.3)), rigid([0.3, 0.5, 0.2], [0.1, -0.1, 2.2])),
        (trimesh.creation.icosphere(subdivisions=3, radius=0.35), rigid([0, 0, 0], [-0.45, 0.25, 1.6])),
        (trimesh.creation.cylinder(radius=0.2, height=1.2, sections=48), rigid([1.2, 0.0, 0.4], [0.55, 0.3, 3.0])),
    ]


def draw(r, meshes, sun=(0.0, 0.0, -1.0)):
    for mesh, _ in meshes:
        corners = mesh.vertices[mesh.faces.ravel()]
        normals = np.repeat(mesh.face_normals, 3, axis=0)
        r.add_mesh(corners, np.arange(len(corners)).reshape(-1, 3), normals, (0.8, 0.6, 0.4))
    return r.render([T for _, T in meshes], None if sun is None else np.asarray(sun, dtype=float))


def ray_cast(meshes, K, width, height):
    """Depth along z of the first hit of the ray through every pixel centre (OpenCV: integer
    coordinates), 0 where none: trimesh's ray caster on Embree, in float64 geometry."""
    import trimesh

    world = trimesh.util.concatenate([m.copy().apply_transform(T) for m, T in meshes])
    intersector = trimesh.ray.ray_pyembree.RayMeshIntersector(world)
    u, v = np.meshgrid(np.arange(width, dtype=float), np.arange(height, dtype=float))
    directions = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(u)], axis=-1).reshape(-1, 3)
    origins = np.zeros_like(directions)
    locations, index_ray, _ = intersector.intersects_location(origins, directions, multiple_hits=False)
    depth = np.zeros(width * height)
    depth[index_ray] = locations[:, 2]
    return depth.reshape(height, width)


def test_depth_matches_an_independent_ray_caster_with_an_off_centre_principal_point():
    meshes = scene()
    r = renderer()
    _, depth = draw(r, meshes)
    r.release()
    reference = ray_cast(meshes, K, W, H)
    hit, expected = depth > 0, reference > 0
    assert expected.mean() > 0.3  # the scene fills a good part of the image
    agreement = (hit == expected).mean()
    assert agreement >= 0.9999, f"coverage differs on {(hit != expected).sum()} of {hit.size} pixels"
    both = hit & expected
    error = np.abs(depth[both].astype(np.float64) - reference[both])
    assert np.percentile(error, 99) <= 1e-5, f"p99 depth error {np.percentile(error, 99):.3g} m"


def test_a_plate_at_a_known_distance_has_its_analytic_depth_and_edges():
    """A 1 m square plate facing the camera, its face at z = 2 m: depth 2 m (to float32) on every
    pixel whose centre projects inside it, 0 elsewhere (OpenCV pixel centres: x = (u - cx) z / fx)."""
    import trimesh

    plate = trimesh.creation.box(extents=(1.0, 1.0, 0.01))
    r = renderer()
    # its edges fall 0.2-0.3 px past pixel centres: half a pixel off moves a row or a column
    _, depth = draw(r, [(plate, rigid([0, 0, 0], [0.1, -0.02, 2.005]))])
    r.release()
    u, v = np.meshgrid(np.arange(W), np.arange(H))
    x, y = (u - K[0, 2]) * 2.0 / K[0, 0], (v - K[1, 2]) * 2.0 / K[1, 1]
    inside = (np.abs(x - 0.1) < 0.5) & (np.abs(y + 0.02) < 0.5)
    assert np.array_equal(depth > 0, inside)
    assert np.max(np.abs(depth[inside] - 2.0)) <= 2.0 * np.finfo(np.float32).eps * 2


@needs("vision", "OpenCV's projection")
def test_points_land_where_opencv_projects_them():
    """Quads in general poses seen by a camera turned and moved (rvec, tvec): a quad's image is the
    polygon of its corners' projections, so every pixel centre inside the polygon OpenCV's
    cv2.projectPoints gives (more than 1e-3 px from its edges) is covered, and every one outside
    is not. Half a pixel off, or an axis swapped, fails on hundreds of pixels."""
    import cv2
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(5)
    rvec, tvec = np.array([0.1, -0.2, 0.15]), np.array([0.05, 0.1, 3.0])
    T_camera_W = rigid(rvec, tvec)
    square = np.array([[-0.3, -0.25, 0.0], [0.3, -0.25, 0.0], [0.3, 0.25, 0.0], [-0.3, 0.25, 0.0]])
    checked = 0
    for _ in range(6):
        T_W_quad = rigid(Rotation.random(random_state=rng).as_rotvec() * 0.6, rng.uniform(-0.6, 0.6, 3))
        corners_W = square @ T_W_quad[:3, :3].T + T_W_quad[:3, 3]
        r = renderer()
        normal = np.tile(T_W_quad[:3, 2], (6, 1))
        r.add_mesh(corners_W[[0, 1, 2, 0, 2, 3]], np.arange(6).reshape(2, 3), normal, (1.0, 1.0, 1.0))
        _, depth = r.render([T_camera_W], None)
        r.release()
        projected, _ = cv2.projectPoints(corners_W, rvec, tvec, K, None)
        polygon = projected.reshape(-1, 1, 2).astype(np.float32)
        for v in range(H):
            for u in range(W):
                distance = cv2.pointPolygonTest(polygon, (float(u), float(v)), True)
                if abs(distance) > 1e-3:
                    assert (depth[v, u] > 0) == (distance > 0), (u, v, distance)
                    checked += distance > 0
    assert checked > 2000


def test_same_pixels_bit_for_bit_on_two_renderers():
    meshes = scene()
    a, b = renderer(), renderer()
    rgb_a, depth_a = draw(a, meshes, sun=(0.3, -0.5, -0.8))
    rgb_b, depth_b = draw(b, meshes, sun=(0.3, -0.5, -0.8))
    rgb_again, depth_again = a.render([T for _, T in meshes], np.array([0.3, -0.5, -0.8]))
    a.release(), b.release()
    assert rgb_a.tobytes() == rgb_b.tobytes() == rgb_again.tobytes()
    assert depth_a.tobytes() == depth_b.tobytes() == depth_again.tobytes()
    assert rgb_a.max() > 50  # lit: the test compares real images


def test_lambert_shading_of_a_plate_facing_the_camera():
    """A plate facing the camera (its normal -z) lit from 60 deg off its normal: colour * (ambient +
    cos 60 deg); with no Sun (eclipse): colour * ambient; the sky black."""
    import trimesh

    plate = trimesh.creation.box(extents=(1.0, 1.0, 0.01))
    pose = rigid([0, 0, 0], [0.0, 0.0, 2.0])
    sun = np.array([np.sin(np.radians(60)), 0.0, -np.cos(np.radians(60))])
    r = renderer()
    rgb, depth = draw(r, [(plate, pose)], sun=sun)
    dark, _ = r.render([pose], None)
    r.release()
    inside = depth > 0
    expected = np.array([0.8, 0.6, 0.4]) * (0.1 + 0.5) * 255
    assert np.all(np.abs(rgb[inside].astype(float) - expected) <= 1.0)
    assert np.all(np.abs(dark[inside].astype(float) - np.array([0.8, 0.6, 0.4]) * 0.1 * 255) <= 1.0)
    assert not rgb[~inside].any()


def test_a_lamp_at_the_camera_lights_a_turned_plate_by_lambert_and_the_inverse_square_law():
    """A plate 0.5 m ahead, turned 35 deg about y and filling the image, lit by the Sun (n . s =
    0.3) and by a lamp at the camera's origin: every pixel is colour * (n . s + lamp cos(i) / d^2),
    d the distance from the camera to the point the pixel's ray meets the plate's plane (ray and
    plane intersected here in float64) and i the angle between the plate's normal and that ray;
    the lamp's share alone (no Sun) likewise, within one count of 255."""
    import trimesh

    from components.camera.render import Renderer

    plate = trimesh.creation.box(extents=(3.0, 3.0, 0.01))
    pose = rigid([0.0, np.radians(35.0), 0.0], [0.05, -0.02, 0.5])
    n = pose[:3, :3] @ [0.0, 0.0, -1.0]  # the face towards the camera
    point = pose[:3, 3] + 0.005 * n  # on that face
    sun = np.cross(n, [0.0, 1.0, 0.0])
    sun = 0.3 * n + np.sqrt(1.0 - 0.09) * sun / np.linalg.norm(sun)
    lamp = 0.05
    colour = np.array([0.8, 0.6, 0.4])
    u, v = np.meshgrid(np.arange(W, dtype=float), np.arange(H, dtype=float))
    rays = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(u)], axis=-1)
    t = (point @ n) / (rays @ n)
    d = t * np.linalg.norm(rays, axis=-1)
    cos_i = np.abs(rays @ n) / np.linalg.norm(rays, axis=-1)
    r = Renderer(K, W, H, 0.05, 100.0, ambient=0.0, lamp=lamp)
    rgb, depth = draw(r, [(plate, pose)], sun=sun)
    lamp_only, _ = r.render([pose], None)
    r.release()
    assert (depth > 0).all()
    for image, light in ((rgb, 0.3 + lamp * cos_i / d**2), (lamp_only, lamp * cos_i / d**2)):
        assert light.max() < 1.0 and np.ptp(light) > 0.05  # unclipped, and varying over the image
        expected = colour * light[..., None] * 255.0
        assert np.abs(image.astype(float) - expected).max() <= 1.0


def test_the_sun_is_where_the_astronomical_almanac_puts_it():
    """ERFA's epv00 Sun against the Almanac's low-precision formula (0.01 deg, mean equator and
    equinox of date: turned into GCRF with the IAU 2006 precession matrix), over four seasons."""
    import erfa

    from components.camera.sun import sun_direction_eci
    from components.timescales import parse_utc, utc_to_tt

    for date in ("2022-09-18T12:00:00Z", "2024-03-20T03:06:00Z", "2025-06-21T00:00:00Z", "2030-12-25T18:30:00Z"):
        tt = utc_to_tt(parse_utc(date))
        n = tt[0] + tt[1] - 2451545.0
        g = np.radians(357.528 + 0.9856003 * n)
        ecliptic_longitude = np.radians(280.460 + 0.9856474 * n + 1.915 * np.sin(g) + 0.020 * np.sin(2 * g))
        obliquity = np.radians(23.439 - 4e-7 * n)
        of_date = np.array(
            [
                np.cos(ecliptic_longitude),
                np.cos(obliquity) * np.sin(ecliptic_longitude),
                np.sin(obliquity) * np.sin(ecliptic_longitude),
            ]
        )
        almanac = erfa.pmat06(*tt).T @ of_date
        angle = np.degrees(np.arccos(np.clip(almanac @ sun_direction_eci(tt), -1.0, 1.0)))
        assert angle < 0.015, (date, angle)


def test_earth_shadow_cylinder():
    from components.camera.sun import R_EARTH, in_earth_shadow

    sun = np.array([1.0, 0.0, 0.0])
    r = 6778e3
    assert in_earth_shadow([-r, 0.0, 0.0], sun)  # behind the Earth
    assert not in_earth_shadow([r, 0.0, 0.0], sun)  # facing the Sun
    assert not in_earth_shadow([0.0, r, 0.0], sun)  # beside it
    assert in_earth_shadow([-r, R_EARTH - 1.0, 0.0], sun)  # just inside the cylinder
    assert not in_earth_shadow([-r, R_EARTH + 1.0, 0.0], sun)  # just outside


def test_a_textured_mesh_from_a_urdf_shows_its_texels_where_they_project(tmp_path):
    """A 1 m plate (an .obj with a 6x6 random black-and-white texture, as trimesh writes it, in a
    URDF) facing the camera 2 m away, lit head-on: the pixel nearest each texel's centre has that
    texel's value (linear filtering blends less than 3 % that close to a texel's centre, 19 pixels
    a texel); the texture upside down or mirrored fails on about half of them."""
    import trimesh
    from PIL import Image

    from components.camera.scene import visual_meshes
    from components.viewer.robot import read_geometry

    pattern = np.random.default_rng(2).integers(0, 2, (6, 6)).astype(np.uint8) * 255
    corners = np.array([[-0.5, -0.5, 0.0], [0.5, -0.5, 0.0], [0.5, 0.5, 0.0], [-0.5, 0.5, 0.0]])
    plate = trimesh.Trimesh(vertices=corners, faces=[[0, 1, 2], [0, 2, 3]], process=False)
    plate.visual = trimesh.visual.TextureVisuals(
        uv=corners[:, :2] + 0.5, image=Image.fromarray(np.repeat(pattern[:, :, None], 3, axis=2))
    )
    plate.export(tmp_path / "plate.obj")
    (tmp_path / "plate.urdf").write_text(
        '<robot name="plate"><link name="plate"><inertial><mass value="1"/><inertia ixx="1" ixy="0" ixz="0" '
        'iyy="1" iyz="0" izz="1"/></inertial><visual><geometry><mesh filename="plate.obj"/></geometry></visual>'
        "</link></robot>"
    )
    meshes, notes = visual_meshes(read_geometry(tmp_path / "plate.urdf"))
    assert not notes and len(meshes) == 1 and meshes[0].texture is not None
    r = renderer()
    r.ambient = 0.0
    m = meshes[0]
    r.add_mesh(m.vertices, np.arange(len(m.vertices)).reshape(-1, 3), m.normals, m.colours, m.uv, m.texture)
    pose = rigid([0, 0, 0], [0.0, 0.0, 2.0])
    rgb, _depth = r.render([pose], np.array([0.0, 0.0, -1.0]))
    r.release()
    for row in range(6):
        for col in range(6):
            x, y = -0.5 + (col + 0.5) / 6, 0.5 - (row + 0.5) / 6  # texel centre on the plate (uv up = image top)
            u, v = round(K[0, 0] * x / 2.0 + K[0, 2]), round(K[1, 1] * y / 2.0 + K[1, 2])
            assert abs(int(rgb[v, u, 0]) - int(pattern[row, col])) <= 10, (row, col, rgb[v, u], pattern[row, col])


def test_a_meshs_face_colours_are_kept_and_a_plain_shape_takes_the_urdf_colour(tmp_path):
    import trimesh

    from components.camera.scene import visual_meshes
    from components.viewer.robot import read_geometry

    box = trimesh.creation.box(extents=(0.2, 0.2, 0.2))
    box.visual.face_colors = np.array([[255, 0, 0, 255] if i % 2 else [0, 0, 255, 255] for i in range(len(box.faces))])
    box.export(tmp_path / "box.ply")
    (tmp_path / "two.urdf").write_text(
        '<robot name="two"><material name="green"><color rgba="0 1 0 1"/></material><link name="a">'
        '<inertial><mass value="1"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial>'
        '<visual><geometry><mesh filename="box.ply"/></geometry><material name="green"/></visual>'
        '<visual><geometry><sphere radius="0.1"/></geometry><material name="green"/></visual></link></robot>'
    )
    (coloured, plain), _ = visual_meshes(read_geometry(tmp_path / "two.urdf"))
    assert {tuple(c) for c in coloured.colours} == {(1.0, 0.0, 0.0), (0.0, 0.0, 1.0)}
    assert {tuple(c) for c in plain.colours} == {(0.0, 1.0, 0.0)}


@needs("vision", "OpenCV's undistortion")
def test_a_distorted_camera_sees_what_opencvs_undistortion_says_each_pixel_sees():
    """plumb_bob distortion (barrel, tangential terms, an off-centre principal point): for every
    pixel, OpenCV's cv2.undistortPoints (200 iterations) gives its ray; the ray meets a tilted plate or not,
    and at what depth. The rendered mask agrees on every pixel whose ray is more than 1.5 px from
    the plate's edges, and the depth is the ray's to within the change of depth over 0.5 px (the
    lens takes each pixel from the pinhole render's nearest, at twice the focal length)."""
    import cv2

    from components.camera.lens import Lens
    from components.camera.render import Renderer

    D = np.array([-0.25, 0.08, 0.001, -0.0015, 0.01])
    lens = Lens(K, W, H, D, supersample=2)
    r = Renderer(lens.K_render, lens.render_width, lens.render_height, 0.05, 100.0)
    half = 0.9
    corners = np.array([[-half, -half, 0.0], [half, -half, 0.0], [half, half, 0.0], [-half, half, 0.0]])
    r.add_mesh(corners[[0, 1, 2, 0, 2, 3]], np.arange(6).reshape(2, 3), np.tile([0.0, 0.0, 1.0], (6, 1)), (1, 1, 1))
    pose = rigid([0.35, -0.25, 0.0], [0.2, 0.1, 2.2])
    rgb, depth = lens.apply(*r.render([pose], None))
    r.release()
    assert depth.shape == (H, W) and rgb.shape == (H, W, 3)
    u, v = np.meshgrid(np.arange(W, dtype=np.float64), np.arange(H, dtype=np.float64))
    pixels = np.stack([u.ravel(), v.ravel()], axis=-1).reshape(-1, 1, 2)
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-14)
    rays = cv2.undistortPoints(pixels, K, D, None, None, None, criteria).reshape(H, W, 2)
    rays = np.concatenate([rays, np.ones((H, W, 1))], axis=-1)
    back, _ = cv2.projectPoints(rays.reshape(-1, 3), np.zeros(3), np.zeros(3), K, D)  # OpenCV converged
    assert np.max(np.abs(back.reshape(H, W, 2) - pixels.reshape(H, W, 2))) < 1e-6
    normal, origin = pose[:3, 2], pose[:3, 3]
    t = (normal @ origin) / (rays @ normal)
    on_plane = (rays * t[..., None] - origin) @ pose[:3, :3]  # plate coordinates
    expected = t  # rays have z = 1: t is the depth
    slack = 1.5 * np.max(expected) / K[0, 0] / abs(normal[2])  # 1.5 px on the tilted plate (m)
    edge = half - np.max(np.abs(on_plane[..., :2]), axis=-1)  # > 0 inside
    sure = np.abs(edge) > slack
    assert sure.mean() > 0.9 and (edge > slack).mean() > 0.3
    assert np.array_equal((depth > 0)[sure], (edge > 0)[sure])
    step = np.maximum(np.abs(np.gradient(expected, axis=0)), np.abs(np.gradient(expected, axis=1)))
    inside = edge > slack
    assert np.all(np.abs(depth[inside] - expected[inside]) <= 0.5 * step[inside] + 1e-5)
    # the pinhole image of the same scene differs by many pixels at the edges: the test sees distortion
    r = renderer()
    r.add_mesh(corners[[0, 1, 2, 0, 2, 3]], np.arange(6).reshape(2, 3), np.tile([0.0, 0.0, 1.0], (6, 1)), (1, 1, 1))
    _, pinhole = r.render([pose], None)
    r.release()
    assert ((pinhole > 0) != (depth > 0)).sum() > 1000


def test_two_cameras_in_one_process_each_draw_their_own_scene():
    """Two renderers made one after the other (two cameras in a process group, or a sensor.camera
    beside a component embedding one): each draws its own meshes in its own context."""
    import trimesh

    plate = trimesh.creation.box(extents=(1.0, 1.0, 0.01))
    a, b = renderer(), renderer()
    draw(a, [(plate, rigid([0, 0, 0], [0.0, 0.0, 2.005]))])
    draw(b, [(plate, rigid([0, 0, 0], [0.0, 0.0, 3.005]))])
    _, depth_a = a.render([rigid([0, 0, 0], [0.0, 0.0, 2.005])], None)
    _, depth_b = b.render([rigid([0, 0, 0], [0.0, 0.0, 3.005])], None)
    a.release()
    _, depth_b_again = b.render([rigid([0, 0, 0], [0.0, 0.0, 3.005])], None)
    b.release()
    assert set(np.unique(depth_a)) == {0.0, np.float32(2.0)}
    assert set(np.unique(depth_b)) == {0.0, np.float32(3.0)}
    assert depth_b_again.tobytes() == depth_b.tobytes()
