"""The analytic camera: the arm drawn as shaded polygons over a board image rendered once per scene.

The camera, the board and the light are fixed, so everything but the arm is one image: TinyRenderer draws the
mirrored scene once with the arm moved out of sight (board texture, markers, frame, shading, background), and
that image and its segmentation are kept. A frame then only poses the arm (PyBullet's forward kinematics in the
mirrored scene):

- each visual shape of the description (cylinders and boxes, :func:`shape_mesh`) is a convex polygon mesh; its
  faces that look at the camera are filled in painter's order (far to near by the face centre's depth) with
  TinyRenderer's shading ``c (AMBIENT + DIFFUSE max(n . l, 0))``, flat per face;
- the arm's shadow on the board: TinyRenderer casts shadows from a point light ``LIGHT_DISTANCE_M`` from the
  world origin along the light direction (its shadow map is a perspective view from there); a convex solid's
  shadow on a plane from a point is the convex hull of its vertices' shadows, so each shape's hull is filled
  there (projected into the image); a shadowed pixel of the board keeps its ambient light and ``SHADOW_KEEP``
  of the rest, as TinyRenderer's shadow map does;
- the board pixels that no shape covers are the visible board handed to :func:`~sim.camera.composite_dirt`,
  as TinyRenderer's segmentation is.

The arm is taken to be in front of the board (it works on the board's front face): the board never hides it.
Not drawn: the arm's shadow on itself, specular highlights, smooth shading across a cylinder's faces.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import pybullet as pb

from .camera import BOARD_RGB, projection_matrix, view_matrix
from .params import CameraParams
from .world import World

#: TinyRenderer's light (PyBullet's getCameraImage defaults): ambient and diffuse coefficients.
AMBIENT, DIFFUSE = 0.6, 0.35
#: Share of the non-ambient light a shadowed pixel keeps in TinyRenderer (its shadow map's 0.8; measured on its
#: frames: a clean wall-board pixel 205 lit, 193 shadowed).
SHADOW_KEEP = 0.8
#: Where TinyRenderer's shadows come from: a point this far from the world origin along the light direction
#: (PyBullet's default ``lightDistance``) [m].
LIGHT_DISTANCE_M = 2.0
#: Sides of the polygon standing for a cylinder's circle.
CYLINDER_SIDES = 24
#: Sub-pixel bits of the polygon corners given to OpenCV's fill.
_SHIFT = 4
#: Where the arm goes while the board's image is rendered: far outside the camera's view and the light's.
_AWAY_M = (0.0, 0.0, -1000.0)
#: How the arm looks: its description's colours, or a real iiwa's (:func:`iiwa_shapes`).
LOOKS = ("description", "iiwa")
#: A real iiwa's links (light grey), and its joints, wrist and cable (dark), RGBA 0-1.
IIWA_LINK_RGB, IIWA_DARK_RGB = (0.86, 0.87, 0.88, 1.0), (0.17, 0.17, 0.19, 1.0)
#: The last arm link (PyBullet index of iiwa_link_7): the wrist and flange, dark.
IIWA_WRIST_LINK = 6
#: Length of a joint's dark ring [m], and the radius of the cable along the links [m].
IIWA_RING_M, CABLE_RADIUS_M = 0.03, 0.012


def cylinder_mesh(radius_m: float, length_m: float, sides: int = CYLINDER_SIDES) -> tuple[np.ndarray, list]:
    """Vertices (2 sides, 3) [m] and faces (lists of vertex indices, counter-clockwise seen from outside) of a
    cylinder along z centred on the origin: ``sides`` side quads and the two end caps."""
    a = 2.0 * np.pi * np.arange(sides) / sides
    ring = np.column_stack([radius_m * np.cos(a), radius_m * np.sin(a)])
    v = np.vstack([np.column_stack([ring, np.full(sides, -length_m / 2)]),
                   np.column_stack([ring, np.full(sides, length_m / 2)])])
    faces = [[i, (i + 1) % sides, sides + (i + 1) % sides, sides + i] for i in range(sides)]
    faces += [list(range(sides - 1, -1, -1)), list(range(sides, 2 * sides))]
    return v, faces


def box_mesh(size_m: np.ndarray) -> tuple[np.ndarray, list]:
    """Vertices (8, 3) [m] and the six faces of a box of edge lengths ``size_m`` (3,) centred on the origin."""
    v = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float) * np.asarray(size_m) / 2
    faces = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]
    return v, faces


def shape_mesh(geometry: int, dims: tuple) -> tuple[np.ndarray, list]:
    """The mesh of a PyBullet visual shape (``getVisualShapeData``'s geometry type and dimensions)."""
    if geometry == pb.GEOM_CYLINDER:
        return cylinder_mesh(dims[1], dims[0])
    if geometry == pb.GEOM_BOX:
        return box_mesh(np.asarray(dims[:3], float))
    raise ValueError(f"the analytic camera draws cylinders and boxes, not PyBullet geometry type {geometry}")


def face_frames(v: np.ndarray, faces: list) -> tuple[np.ndarray, np.ndarray]:
    """Centres (F, 3) and outward unit normals (F, 3) of the faces of a convex mesh centred on the origin
    (Newell's normal, turned away from the origin)."""
    centres, normals = [], []
    for f in faces:
        p = v[f]
        n = np.cross(p, np.roll(p, -1, axis=0)).sum(axis=0)
        c = p.mean(axis=0)
        n = n if n @ c >= 0 else -n
        centres.append(c)
        normals.append(n / np.linalg.norm(n))
    return np.array(centres), np.array(normals)


def matrix_from_xyzw(q: tuple) -> np.ndarray:
    """(3, 3) rotation of a PyBullet (scalar-last) quaternion."""
    return np.array(pb.getMatrixFromQuaternion(q)).reshape(3, 3)


@dataclass(frozen=True)
class ArmMesh:
    """The arm's visual shapes as one polygon mesh in the frames of their links.

    vertices : (V, 3) [m] in the link frame; vertex_link : (V,) index into ``links``; shape_vertices : a slice
    of ``vertices`` per shape; faces : vertex indices per face; centres, normals : (F, 3) per face in the link
    frame; face_link : (F,); face_rgb : (F, 3) colour 0-255; links : PyBullet link indices (-1 the base).
    """

    vertices: np.ndarray
    vertex_link: np.ndarray
    shape_vertices: tuple[slice, ...]
    faces: tuple[np.ndarray, ...]
    centres: np.ndarray
    normals: np.ndarray
    face_link: np.ndarray
    face_rgb: np.ndarray
    links: tuple[int, ...]


def iiwa_shapes(link: int, geometry: int, dims: tuple, rgba: tuple, pos: tuple, orn: tuple) -> list[tuple]:
    """A visual shape of the description as a real iiwa looks (:data:`LOOKS` ``"iiwa"``): each arm link's
    cylinder light grey (:data:`IIWA_LINK_RGB`), a dark joint ring (:data:`IIWA_DARK_RGB`) over its base end, a
    dark cable (:data:`CABLE_RADIUS_M`) along its side, the wrist (the last link) dark; other shapes (the
    eraser) as described. Items ``(geometry, dims, rgba, pos, orn)``, frames relative to the link."""
    if geometry != pb.GEOM_CYLINDER or link > IIWA_WRIST_LINK:
        return [(geometry, dims, rgba, pos, orn)]
    length, radius = dims[0], dims[1]
    if link == IIWA_WRIST_LINK:
        return [(geometry, dims, IIWA_DARK_RGB, pos, orn)]
    R = matrix_from_xyzw(orn)
    p = np.asarray(pos, float)
    ring_len = min(IIWA_RING_M, length / 3)
    ring_at = p + R @ np.array([0.0, 0.0, -length / 2 + ring_len / 2])
    cable_at = p + R @ np.array([radius + CABLE_RADIUS_M, 0.0, 0.0])
    return [(geometry, dims, IIWA_LINK_RGB, pos, orn),
            (geometry, (ring_len, radius * 1.04), IIWA_DARK_RGB, tuple(ring_at), orn),
            (geometry, (length, CABLE_RADIUS_M), IIWA_DARK_RGB, tuple(cable_at), orn)]


def arm_mesh(client: int, robot: int, look: str = "description") -> ArmMesh:
    """The visual shapes of ``robot`` in PyBullet client ``client`` (their frames relative to the link frames),
    coloured as the description says or, ``look="iiwa"``, as a real iiwa (:func:`iiwa_shapes`)."""
    if look not in LOOKS:
        raise ValueError(f"look must be one of {LOOKS}, got {look!r}")
    links = sorted({v[1] for v in pb.getVisualShapeData(robot, physicsClientId=client)})
    verts, vlink, slices, faces, centres, normals, flink, rgb = [], [], [], [], [], [], [], []
    n = 0
    shapes: list[tuple] = []
    for shape in pb.getVisualShapeData(robot, physicsClientId=client):
        item = (shape[1], shape[2], shape[3], shape[7], shape[5], shape[6])
        shapes += [(item[0], *s) for s in iiwa_shapes(*item)] if look == "iiwa" else [item]
    for link, geometry, dims, rgba, pos, orn in shapes:
        v, f = shape_mesh(geometry, dims)
        c, nrm = face_frames(v, f)
        R, p = matrix_from_xyzw(orn), np.asarray(pos, float)
        verts.append(v @ R.T + p)
        centres.append(c @ R.T + p)
        normals.append(nrm @ R.T)
        li = links.index(link)
        vlink.append(np.full(len(v), li))
        flink.append(np.full(len(f), li))
        rgb.append(np.tile(np.asarray(rgba[:3], float) * 255.0, (len(f), 1)))
        faces += [np.asarray(fi) + n for fi in f]
        slices.append(slice(n, n + len(v)))
        n += len(v)
    return ArmMesh(np.vstack(verts), np.concatenate(vlink), tuple(slices), tuple(faces), np.vstack(centres),
                   np.vstack(normals), np.concatenate(flink), np.vstack(rgb), tuple(links))


def shadow_on_plane(points_m: np.ndarray, origin_m: np.ndarray, normal: np.ndarray, light_m: np.ndarray
                    ) -> np.ndarray:
    """Shadows (n, 3) [m] of points (n, 3) [m] cast from a point light at ``light_m`` (3,) on the plane through
    ``origin_m`` (3,) with unit ``normal`` (3,): ``L + t (p - L)`` with ``t = ((o - L) . n) / ((p - L) . n)``.

    Points no nearer the plane than the light (``t <= 1`` is where they lie between it and the plane) are
    clamped to just in front of the light's height over the plane, so their shadows go far but stay finite.
    """
    h_light = (light_m - origin_m) @ normal
    h = np.minimum((points_m - origin_m) @ normal, 0.99 * h_light)
    t = -h_light / (h - h_light)
    return light_m + t[:, None] * (points_m - light_m)


class AnalyticCamera:
    """The analytic renderer of one scene (a mirrored PyBullet client with the textured board, see
    :func:`sim.world.build_world`): :meth:`render` draws a frame for joint positions ``q``.

    T_camera_to_world : (4, 4) optical frame; light : (3,) unit direction towards the light.
    """

    def __init__(self, world: World, cam: CameraParams, k, T_camera_to_world: np.ndarray, light: np.ndarray,
                 board_origin_m: np.ndarray, board_normal: np.ndarray, look: str = "description") -> None:
        self.world, self.cam = world, cam
        self.fx, self.fy, self.cx, self.cy = k.fx, k.fy, k.cx, k.cy
        self.R_cam, self.o_cam = T_camera_to_world[:3, :3].copy(), T_camera_to_world[:3, 3].copy()
        self.light = np.asarray(light, float) / np.linalg.norm(light)
        self.board_origin, self.board_normal = np.asarray(board_origin_m, float), np.asarray(board_normal, float)
        c = world.client
        self.mesh = arm_mesh(c, world.robot, look)
        base_pos, base_orn = pb.getBasePositionAndOrientation(world.robot, physicsClientId=c)
        inertial_pos, inertial_orn = pb.getDynamicsInfo(world.robot, -1, physicsClientId=c)[3:5]
        frame_pos, frame_orn = pb.multiplyTransforms(base_pos, base_orn,
                                                     *pb.invertTransform(inertial_pos, inertial_orn))
        self._base = (matrix_from_xyzw(frame_orn), np.asarray(frame_pos, float))
        self._moving = [li for li in self.mesh.links if li >= 0]
        self.background, segmentation = self._empty_scene(T_camera_to_world, k)
        self.board_mask = segmentation == world.board  # (H * W,)
        surface = (segmentation >= 0).reshape(cam.height, cam.width)
        lit = float(np.median(self.background.reshape(-1, 3)[self.board_mask].mean(axis=1))) / float(BOARD_RGB.mean())
        keep = min(1.0, (AMBIENT + SHADOW_KEEP * (lit - AMBIENT)) / lit) if lit > AMBIENT else 1.0
        shaded = np.clip(self.background * keep + 0.5, 0, 255).astype(np.uint8)
        self.shadowed = np.where(surface[..., None], shaded, self.background)
        self.light_m = LIGHT_DISTANCE_M * self.light
        self.casts_shadow = bool(cam.shadow) and float((self.light_m - self.board_origin) @ self.board_normal) > 0.0
        self._shadow = np.zeros((cam.height, cam.width), np.uint8)
        self._arm = np.zeros((cam.height, cam.width), np.uint8)

    def _empty_scene(self, T_camera_to_world: np.ndarray, k) -> tuple[np.ndarray, np.ndarray]:
        """TinyRenderer's image (H, W, 3) of the scene without the arm, and its segmentation (H * W,)."""
        c, robot, cam = self.world.client, self.world.robot, self.cam
        pos, orn = pb.getBasePositionAndOrientation(robot, physicsClientId=c)
        pb.resetBasePositionAndOrientation(robot, _AWAY_M, orn, physicsClientId=c)
        try:
            out = pb.getCameraImage(cam.width, cam.height, view_matrix(T_camera_to_world), projection_matrix(k),
                                    renderer=pb.ER_TINY_RENDERER, shadow=int(cam.shadow),
                                    lightDirection=self.light.tolist(), physicsClientId=c)
        finally:
            pb.resetBasePositionAndOrientation(robot, pos, orn, physicsClientId=c)
        rgb = np.asarray(out[2], np.uint8).reshape(cam.height, cam.width, 4)[..., :3].copy()
        return rgb, np.asarray(out[4]).reshape(-1).copy()

    def link_poses(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rotations (L, 3, 3) and positions (L, 3) [m] of the mesh's link frames at joint positions ``q``."""
        c, robot = self.world.client, self.world.robot
        for j, qj in zip(self.world.joints, q):
            pb.resetJointState(robot, j, float(qj), physicsClientId=c)
        states = pb.getLinkStates(robot, self._moving, computeForwardKinematics=True, physicsClientId=c)
        by_link = {li: (matrix_from_xyzw(s[5]), np.asarray(s[4], float)) for li, s in zip(self._moving, states)}
        by_link[-1] = self._base
        poses = [by_link[li] for li in self.mesh.links]
        return np.array([r for r, _ in poses]), np.array([p for _, p in poses])

    def _pixels(self, p_world_m: np.ndarray) -> np.ndarray:
        """Fixed-point pixel coordinates (n, 2) int32 (``_SHIFT`` fraction bits) of world points (n, 3)."""
        pc = (p_world_m - self.o_cam) @ self.R_cam
        z = np.maximum(pc[:, 2], 1e-6)
        uv = np.column_stack([self.fx * pc[:, 0] / z + self.cx, self.fy * pc[:, 1] / z + self.cy])
        return np.round(uv * (1 << _SHIFT)).astype(np.int32)

    def _hulls(self, target: np.ndarray, pixels: np.ndarray) -> None:
        """Fill, in ``target``, the convex hull of each shape's vertex pixels."""
        target[...] = 0
        for sl in self.mesh.shape_vertices:
            cv2.fillConvexPoly(target, cv2.convexHull(pixels[sl]), 1, cv2.LINE_8, _SHIFT)

    def render(self, image: np.ndarray, q: np.ndarray) -> np.ndarray:
        """Draw into ``image`` (H, W, 3) uint8 RGB the scene with the arm at ``q`` (7,) [rad]; return the mask
        (H * W,) bool of the board pixels the arm leaves visible."""
        m = self.mesh
        R, p = self.link_poses(q)
        verts = np.einsum("vij,vj->vi", R[m.vertex_link], m.vertices) + p[m.vertex_link]
        centres = np.einsum("fij,fj->fi", R[m.face_link], m.centres) + p[m.face_link]
        normals = np.einsum("fij,fj->fi", R[m.face_link], m.normals)
        image[...] = self.background
        if self.casts_shadow:
            self._hulls(self._shadow, self._pixels(shadow_on_plane(verts, self.board_origin, self.board_normal,
                                                                   self.light_m)))
            if cv2.copyTo(self.shadowed, self._shadow, image) is not image:  # in place when image is contiguous
                np.copyto(image, self.shadowed, where=self._shadow[..., None].astype(bool))
        pixels = self._pixels(verts)
        facing = np.einsum("fi,fi->f", normals, self.o_cam - centres) > 0.0
        depth = (centres - self.o_cam) @ self.R_cam[:, 2]
        shade = AMBIENT + DIFFUSE * np.clip(normals @ self.light, 0.0, None)
        colour = np.clip(m.face_rgb * shade[:, None], 0.0, 255.0).round()
        for f in np.flatnonzero(facing)[np.argsort(-depth[facing], kind="stable")]:
            cv2.fillConvexPoly(image, pixels[m.faces[f]], colour[f].tolist(), cv2.LINE_8, _SHIFT)
        self._hulls(self._arm, pixels)
        return self.board_mask & (self._arm.reshape(-1) == 0)
