"""The MuJoCo model: compiled from THE robot description, plus the world around it.

`build_model(urdf_text, config, knobs)` compiles the URDF with MuJoCo (never a parallel
hand-written MJCF) and adds, through mujoco.MjSpec: the floor, lights, the marker texture
on the plate's top face, the ball (thin shell, rolling/torsional friction), the fixed
overhead camera, gravity compensation for the arm (as the UR controller does) and a
position servo per joint (gains from the arm's inertia at home for the requested lag).
A domain's `plate_mount_tilt_deg` turns the plate body on the tool flange (about its own
centre and a horizontal plate axis), as a plate mounted off level would be: the controllers'
kinematics (the URDF) do not know it.
No ROS import.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Tuple

import mujoco
import numpy as np

from ball_balance import robot
from ball_balance.plate_geometry import (
    MARKER_CENTRES_M,
    MARKER_SIDE_M,
    PLATE_FRAME,
    PLATE_SIDE_M,
    PLATE_THICKNESS_M,
)
from ball_balance.sim.config import DomainKnobs, SimConfig

BALL_BODY = "ball"
CAMERA_NAME = "overhead_camera"
PLATE_TOP_GEOM = "plate_top"
COLLISION_GROUP = 3  # not drawn by mujoco.Renderer's default scene options
# Contact bits (MuJoCo collides a pair when contype & conaffinity of either side overlap):
# the ball touches the plate and the floor; the plate never touches the floor (a fully
# folded arm would otherwise be pushed by the floor past its joint limits).
PLATE_BIT, FLOOR_BIT = 1, 2
ARMATURE_KG_M2 = (0.2, 0.2, 0.1, 0.02, 0.02, 0.02)  # reflected rotor inertia per joint
TEXTURE_PX_PER_M = 2400.0  # marker side = 96 px = 6 ArUco cells of 16 px
MARKER_QUAD_BORDER_M = 0.004   # plate colour around each marker in its textured quad
MARKER_PATCH_ALIGN_PX = 16     # marker patches start and end on this texture-pixel grid


@dataclass(frozen=True)
class ModelIds:
    """Indices into the compiled model that the world uses every step."""

    qpos_arm: np.ndarray     # qpos address of each joint in JOINT_NAMES order
    dof_arm: np.ndarray      # dof address of each joint
    actuators: np.ndarray    # actuator id of each joint
    plate_body: int
    ball_body: int
    ball_qpos: int           # qpos address of the ball's free joint (x y z qw qx qy qz)
    ball_dof: int
    camera: int


def plate_texture_rgb(px_per_m: float = TEXTURE_PX_PER_M) -> np.ndarray:
    """The plate's top face as an RGB image (rows from plate +y down to -y, columns -x to +x).

    Light matte plate with the four DICT_4X4_50 markers of plate_geometry at their centres,
    axis-aligned with marker "up" = plate +y. Generated with OpenCV at run time.
    """
    import cv2

    side_px = int(round(PLATE_SIDE_M * px_per_m))
    image = np.full((side_px, side_px), 235, dtype=np.uint8)
    dictionary = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50)
    marker_px = int(round(MARKER_SIDE_M * px_per_m))
    half = PLATE_SIDE_M / 2.0
    for marker_id, (x, y) in MARKER_CENTRES_M.items():
        marker = cv2.aruco.generateImageMarker(dictionary, marker_id, marker_px)
        col0 = int(round((x + half) * px_per_m - marker_px / 2.0))
        row0 = int(round((half - y) * px_per_m - marker_px / 2.0))
        image[row0:row0 + marker_px, col0:col0 + marker_px] = marker
    return np.repeat(image[:, :, None], 3, axis=2)


def build_model(urdf_text: str, config: SimConfig = SimConfig(),
                knobs: DomainKnobs = DomainKnobs()) -> Tuple[mujoco.MjModel, ModelIds]:
    """Compile the world. Raises RobotDescriptionError for a URDF without our links/joints."""
    robot.check_robot_description(urdf_text)
    spec = mujoco.MjSpec.from_string(urdf_text)
    spec.compiler.discardvisual = False  # keep our visual-only geoms (texture quad, arm)
    spec.option.timestep = config.physics_dt_s
    spec.option.gravity = [0.0, 0.0, -9.81 * knobs.gravity_scale]
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    spec.option.impratio = 10.0
    offwidth = max(640, config.camera.width_px)
    offheight = max(480, config.camera.height_px)
    spec.visual.global_.offwidth, spec.visual.global_.offheight = offwidth, offheight
    spec.visual.quality.offsamples = config.camera.antialias_samples
    spec.visual.headlight.ambient = [0.25, 0.25, 0.25]
    spec.visual.headlight.diffuse = [0.2, 0.2, 0.2]

    home = _home_plate_pose(urdf_text)
    _add_arm_dynamics(spec, urdf_text)
    _tilt_plate_mount(spec, knobs)
    _add_floor_and_lights(spec, home, knobs)
    _add_plate_texture(spec)
    _add_ball(spec, config, knobs, home)
    _add_camera(spec, config, home)
    model = spec.compile()
    ids = _model_ids(model)
    _tune_servos(model, ids, config)
    return model, ids


def _home_plate_pose(urdf_text: str) -> np.ndarray:
    """T_base_plate (4x4) at HOME_POSITIONS_RAD, from the URDF."""
    kin = robot.UrdfKinematics(urdf_text)
    return kin.transform(PLATE_FRAME, robot.BASE_FRAME, robot.joint_dict(robot.HOME_POSITIONS_RAD))


def _add_arm_dynamics(spec: mujoco.MjSpec, urdf_text: str) -> None:
    """URDF visuals are drawn (group 1); its collision shapes are hidden (group 3) and do not
    collide, except the plate's box (the ball's contact surface). Gravity compensated; servos."""
    for geom in spec.geoms:
        if geom.contype == 0 and geom.conaffinity == 0:
            continue  # a URDF <visual>
        geom.group = COLLISION_GROUP
        if geom.parent.name == PLATE_FRAME and geom.type == mujoco.mjtGeom.mjGEOM_BOX:
            geom.name, geom.contype, geom.conaffinity = "plate", PLATE_BIT, PLATE_BIT
        else:
            geom.contype, geom.conaffinity = 0, 0
    for body in spec.bodies:
        if body.name not in ("world", BALL_BODY):
            body.gravcomp = 1.0
    limits = robot.joint_limits(urdf_text)
    for name, armature in zip(robot.JOINT_NAMES, ARMATURE_KG_M2, strict=True):
        joint = spec.joint(name)
        joint.armature = armature
        actuator = spec.add_actuator(name=name, target=name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        actuator.set_to_position(kp=1.0, kv=0.1)  # gains set after compile (_tune_servos)
        effort = limits[name].effort
        actuator.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
        actuator.forcerange = [-effort, effort]


def plate_mount_quat(tilt_deg: float, axis_deg: float) -> np.ndarray:
    """(w, x, y, z): a turn by `tilt_deg` about the plate axis (cos a, sin a, 0), a = axis_deg."""
    half, a = np.radians(tilt_deg) / 2.0, np.radians(axis_deg)
    return np.array([np.cos(half), np.sin(half) * np.cos(a), np.sin(half) * np.sin(a), 0.0])


def _tilt_plate_mount(spec: mujoco.MjSpec, knobs: DomainKnobs) -> None:
    """The plate body turned on its mount (relative to the flange) by the domain's tilt."""
    if knobs.plate_mount_tilt_deg == 0.0:
        return
    body = spec.body(PLATE_FRAME)
    quat = np.zeros(4)
    mujoco.mju_mulQuat(quat, np.asarray(body.quat, dtype=float),
                       plate_mount_quat(knobs.plate_mount_tilt_deg, knobs.plate_mount_axis_deg))
    body.quat = quat.tolist()


def _add_floor_and_lights(spec: mujoco.MjSpec, home: np.ndarray, knobs: DomainKnobs) -> None:
    floor_mat = spec.add_material(name="floor", rgba=[0.16, 0.17, 0.19, 1.0])
    floor_mat.reflectance = 0.0
    spec.worldbody.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[3.0, 3.0, 0.05],
                            material="floor", contype=FLOOR_BIT, conaffinity=FLOOR_BIT)
    above = home[:3, 3] + np.array([0.0, 0.0, 1.5])
    diffuse = [0.75 * knobs.light_scale] * 3
    spec.worldbody.add_light(name="overhead", pos=above.tolist(), dir=[0.0, 0.0, -1.0],
                             diffuse=diffuse, specular=[0.05, 0.05, 0.05], castshadow=False)


def _add_plate_texture(spec: mujoco.MjSpec) -> None:
    """The plate's top face (visual only; the URDF box stays the collider), showing
    `plate_texture_rgb()`: one small textured quad per marker, cut from that texture on its
    pixel grid, and around them the face in the texture's plate colour.

    Why not one texture over the whole face: the camera is rendered on the CPU (llvmpipe),
    where sampling a large texture costs several times a plain pixel; the face covers about
    40 % of the image, the markers' quads about 2 % (about a quarter less CPU per frame). The
    face is textured too, with one texel, so that it is lit exactly as the markers' surround (a
    texture modulates the clamped lighting, a plain colour does not), and it is a grid whose
    cells include the markers' quads: lighting is computed per vertex, so quads sharing their
    corners show no seam under any light."""
    image = plate_texture_rgb()
    px_per_m = image.shape[0] / PLATE_SIDE_M
    half = PLATE_SIDE_M / 2.0
    z = PLATE_THICKNESS_M / 2.0 + 1e-4
    border_px, align = int(round(MARKER_QUAD_BORDER_M * px_per_m)), MARKER_PATCH_ALIGN_PX
    patches = []       # (marker id, col0, row0, col1, row1) in texture pixels
    for marker_id, (x, y) in sorted(MARKER_CENTRES_M.items()):
        # columns from -x, rows from +y; on a grid of `align` pixels so that the texels of
        # the first mipmap levels line up with the whole texture's
        col0 = max(0, (int((x + half - MARKER_SIDE_M / 2.0) * px_per_m) - border_px) // align * align)
        row0 = max(0, (int((half - y - MARKER_SIDE_M / 2.0) * px_per_m) - border_px) // align * align)
        col1 = min(image.shape[1], -(-(int((x + half + MARKER_SIDE_M / 2.0) * px_per_m) + border_px) // align) * align)
        row1 = min(image.shape[0], -(-(int((half - y + MARKER_SIDE_M / 2.0) * px_per_m) + border_px) // align) * align)
        patches.append((marker_id, col0, row0, col1, row1))

    def x_m(col):
        return col / px_per_m - half

    def y_m(row):
        return half - row / px_per_m

    xs = sorted({-half, half, *(x_m(c) for p in patches for c in p[1::2])})
    ys = sorted({-half, half, *(y_m(r) for p in patches for r in p[2::2])})
    marker_cells = {(x_m(p[1]), y_m(p[4])) for p in patches}            # their (x0, y0) corners
    face_cells = [(x0, y0, x1, y1) for x0, x1 in zip(xs, xs[1:]) for y0, y1 in zip(ys, ys[1:])
                  if (x0, y0) not in marker_cells]
    _add_textured_quads(spec, "plate_top", image[:1, :1], face_cells, z)
    for marker_id, col0, row0, col1, row1 in patches:
        _add_textured_quads(spec, f"plate_marker_{marker_id}", image[row0:row1, col0:col1],
                            [(x_m(col0), y_m(row1), x_m(col1), y_m(row0))], z)


def _add_textured_quads(spec: mujoco.MjSpec, name: str, rgb: np.ndarray, cells, z: float) -> None:
    """A visual-only mesh of rectangles (x0, y0, x1, y1) at height z in the plate frame,
    facing +z, each showing the RGB image `rgb` (row 0 at +y, column 0 at -x), matte."""
    texture = spec.add_texture(name=name, type=mujoco.mjtTexture.mjTEXTURE_2D,
                               width=rgb.shape[1], height=rgb.shape[0], nchannel=3)
    texture.data = np.ascontiguousarray(rgb).tobytes()
    material = spec.add_material(name=name)
    material.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = name
    material.specular, material.shininess, material.reflectance = 0.0, 0.0, 0.0
    vertices, texcoords, faces = [], [], []
    for x0, y0, x1, y1 in cells:
        n = len(vertices) // 3
        vertices += [x0, y0, z, x1, y0, z, x1, y1, z, x0, y1, z]
        texcoords += [0.0, 1.0, 1.0, 1.0, 1.0, 0.0, 0.0, 0.0]
        faces += [n, n + 1, n + 2, n, n + 2, n + 3]
    mesh = spec.add_mesh(name=name)
    mesh.uservert, mesh.usertexcoord, mesh.userface = vertices, texcoords, faces
    mesh.inertia = mujoco.mjtMeshInertia.mjMESH_INERTIA_SHELL
    spec.body(PLATE_FRAME).add_geom(name=name, type=mujoco.mjtGeom.mjGEOM_MESH, meshname=name, material=name,
                                    contype=0, conaffinity=0, group=1, mass=0.0, density=0.0)


def _add_ball(spec: mujoco.MjSpec, config: SimConfig, knobs: DomainKnobs, home: np.ndarray) -> None:
    r = config.ball_radius_m
    m = knobs.ball_mass_kg
    shell = mujoco.mjtGeomInertia.mjINERTIA_SHELL if config.ball_shell else mujoco.mjtGeomInertia.mjINERTIA_VOLUME
    start = home[:3, 3] + home[:3, 2] * (PLATE_THICKNESS_M / 2.0 + r)
    body = spec.worldbody.add_body(name=BALL_BODY, pos=start.tolist())
    body.add_freejoint(name="ball_free")
    ball_mat = spec.add_material(name="ball", rgba=[1.0, 0.45, 0.05, 1.0])
    ball_mat.specular, ball_mat.shininess = 0.1, 0.1
    body.add_geom(name="ball", type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[r, 0, 0], material="ball",
                  mass=m, contype=PLATE_BIT | FLOOR_BIT, conaffinity=PLATE_BIT | FLOOR_BIT, condim=6, priority=1,
                  typeinertia=shell,
                  friction=[knobs.ball_friction, config.torsional_friction_m, config.rolling_friction_m])


def _add_camera(spec: mujoco.MjSpec, config: SimConfig, home: np.ndarray) -> None:
    """Camera axes = plate axes at home (x right, y up; MuJoCo cameras look along -z)."""
    R_WC = home[:3, :3]
    pos = home[:3, 3] + R_WC[:, 2] * config.camera.height_above_plate_m
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, np.ascontiguousarray(R_WC).reshape(9))
    spec.worldbody.add_camera(name=CAMERA_NAME, pos=pos.tolist(), quat=quat.tolist(),
                              fovy=config.camera.fovy_deg)


def _model_ids(model: mujoco.MjModel) -> ModelIds:
    joints = [model.joint(name) for name in robot.JOINT_NAMES]
    ball_joint = model.joint("ball_free")
    return ModelIds(
        qpos_arm=np.array([model.jnt_qposadr[j.id] for j in joints]),
        dof_arm=np.array([model.jnt_dofadr[j.id] for j in joints]),
        actuators=np.array([model.actuator(name).id for name in robot.JOINT_NAMES]),
        plate_body=model.body(PLATE_FRAME).id,
        ball_body=model.body(BALL_BODY).id,
        ball_qpos=int(model.jnt_qposadr[ball_joint.id]),
        ball_dof=int(model.jnt_dofadr[ball_joint.id]),
        camera=model.camera(CAMERA_NAME).id,
    )


def _tune_servos(model: mujoco.MjModel, ids: ModelIds, config: SimConfig) -> None:
    """Critically damped PD per joint: kp = M_ii omega^2, kv = 2 M_ii omega (M at home)."""
    data = mujoco.MjData(model)
    data.qpos[ids.qpos_arm] = robot.HOME_POSITIONS_RAD
    mujoco.mj_forward(model, data)
    M = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, M)
    omega = config.servo_omega_rad_s
    for actuator, dof in zip(ids.actuators, ids.dof_arm, strict=True):
        inertia = M[dof, dof]
        kp, kv = inertia * omega * omega, 2.0 * inertia * omega
        model.actuator_gainprm[actuator, 0] = kp
        model.actuator_biasprm[actuator, 1:3] = (-kp, -kv)
