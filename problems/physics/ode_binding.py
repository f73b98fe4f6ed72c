"""A minimal ctypes binding of the Open Dynamics Engine (ODE 0.16, double precision).

Only the functions the ode engine needs, each bound once with its argument and result types.
Struct layouts and constants are those of ODE 0.16's headers (ode/contact.h, ode/common.h,
ode/mass.h, double precision; the sizes were checked against sizeof in C: dContact 248 bytes,
dJointFeedback 128, dMass 136). The library is found by name: ``METAOPT_ODE_LIBRARY`` (a file
name or path; default libode.so.8, Debian's package libode8).
"""

from __future__ import annotations

import ctypes
import os
from ctypes import POINTER, Structure, c_double, c_int, c_void_p

#: Environment variable naming the ODE shared library to load (path or soname).
LIBRARY_ENV = "METAOPT_ODE_LIBRARY"
DEFAULT_LIBRARY = "libode.so.8"
#: The one command that installs the library on Debian/Ubuntu.
INSTALL_COMMAND = "apt-get install libode8"

dReal = c_double
dVector3 = dReal * 4  # ODE pads 3-vectors to 4
dMatrix3 = dReal * 12

# dContact mode flags (ode/contact.h)
CONTACT_SOFT_ERP = 0x008
CONTACT_SOFT_CFM = 0x010
CONTACT_SLIP1 = 0x100
CONTACT_SLIP2 = 0x200
CONTACT_APPROX1 = 0x7000  # friction pyramid scaled by the normal force: mu is a coefficient

#: dAllocateODEDataForThread flag: the calling thread may run collision detection.
ALLOCATE_COLLISION_DATA = 0x1

# Joint parameters, first group (ode/common.h D_ALL_PARAM_NAMES)
PARAM_LO_STOP = 0
PARAM_HI_STOP = 1
PARAM_VEL = 2
PARAM_FMAX = 5
PARAM_FUDGE_FACTOR = 6
PARAM_BOUNCE = 7
PARAM_CFM = 8
PARAM_STOP_ERP = 9
PARAM_STOP_CFM = 10


class SurfaceParameters(Structure):
    """dSurfaceParameters."""

    _fields_ = [
        ("mode", c_int),
        ("mu", dReal),
        ("mu2", dReal),
        ("rho", dReal),
        ("rho2", dReal),
        ("rhoN", dReal),
        ("bounce", dReal),
        ("bounce_vel", dReal),
        ("soft_erp", dReal),
        ("soft_cfm", dReal),
        ("motion1", dReal),
        ("motion2", dReal),
        ("motionN", dReal),
        ("slip1", dReal),
        ("slip2", dReal),
    ]


class ContactGeom(Structure):
    """dContactGeom: one contact point dCollide reports."""

    _fields_ = [
        ("pos", dVector3),
        ("normal", dVector3),
        ("depth", dReal),
        ("g1", c_void_p),
        ("g2", c_void_p),
        ("side1", c_int),
        ("side2", c_int),
    ]


class Contact(Structure):
    """dContact: surface values, the contact point and the first friction direction."""

    _fields_ = [("surface", SurfaceParameters), ("geom", ContactGeom), ("fdir1", dVector3)]


class JointFeedback(Structure):
    """dJointFeedback: force and torque (about the centre of mass) a joint applied to each body
    during the last step."""

    _fields_ = [("f1", dVector3), ("t1", dVector3), ("f2", dVector3), ("t2", dVector3)]


class Mass(Structure):
    """dMass: mass, centre of mass and inertia tensor (3x4, row-padded)."""

    _fields_ = [("mass", dReal), ("c", dVector3), ("I", dMatrix3)]


_ID = c_void_p
_P = POINTER(dReal)
_SIGNATURES: dict[str, tuple[type | None, list]] = {
    "dInitODE2": (c_int, [ctypes.c_uint]),
    "dAllocateODEDataForThread": (c_int, [ctypes.c_uint]),
    "dGetConfiguration": (ctypes.c_char_p, []),
    "dWorldCreate": (_ID, []),
    "dWorldDestroy": (None, [_ID]),
    "dWorldSetGravity": (None, [_ID, dReal, dReal, dReal]),
    "dWorldSetCFM": (None, [_ID, dReal]),
    "dWorldSetERP": (None, [_ID, dReal]),
    "dWorldSetContactSurfaceLayer": (None, [_ID, dReal]),
    "dWorldSetAutoDisableFlag": (None, [_ID, c_int]),
    "dWorldStep": (c_int, [_ID, dReal]),
    "dBodyCreate": (_ID, [_ID]),
    "dMassSetParameters": (None, [POINTER(Mass), dReal] + [dReal] * 9),
    "dBodySetMass": (None, [_ID, POINTER(Mass)]),
    "dBodyGetMass": (None, [_ID, POINTER(Mass)]),
    "dBodySetPosition": (None, [_ID, dReal, dReal, dReal]),
    "dBodySetQuaternion": (None, [_ID, _P]),
    "dBodySetLinearVel": (None, [_ID, dReal, dReal, dReal]),
    "dBodySetAngularVel": (None, [_ID, dReal, dReal, dReal]),
    "dBodyGetPosition": (_P, [_ID]),
    "dBodyGetQuaternion": (_P, [_ID]),
    "dBodyGetRotation": (_P, [_ID]),
    "dBodyGetLinearVel": (_P, [_ID]),
    "dBodyGetAngularVel": (_P, [_ID]),
    "dBodyGetForce": (_P, [_ID]),
    "dBodyGetTorque": (_P, [_ID]),
    "dCreatePlane": (_ID, [_ID, dReal, dReal, dReal, dReal]),
    "dCreateBox": (_ID, [_ID, dReal, dReal, dReal]),
    "dCreateSphere": (_ID, [_ID, dReal]),
    "dCreateCapsule": (_ID, [_ID, dReal, dReal]),
    "dGeomSetBody": (None, [_ID, _ID]),
    "dGeomDestroy": (None, [_ID]),
    "dCollide": (c_int, [_ID, _ID, c_int, POINTER(ContactGeom), c_int]),
    "dJointGroupCreate": (_ID, [c_int]),
    "dJointGroupEmpty": (None, [_ID]),
    "dJointGroupDestroy": (None, [_ID]),
    "dJointCreateContact": (_ID, [_ID, _ID, POINTER(Contact)]),
    "dJointCreateHinge": (_ID, [_ID, _ID]),
    "dJointAttach": (None, [_ID, _ID, _ID]),
    "dJointSetFeedback": (None, [_ID, POINTER(JointFeedback)]),
    "dJointSetHingeAnchor": (None, [_ID, dReal, dReal, dReal]),
    "dJointSetHingeAxis": (None, [_ID, dReal, dReal, dReal]),
    "dJointSetHingeParam": (None, [_ID, c_int, dReal]),
    "dJointGetHingeParam": (dReal, [_ID, c_int]),
    "dJointGetHingeAngle": (dReal, [_ID]),
    "dJointGetHingeAngleRate": (dReal, [_ID]),
}


class OdeUnavailable(RuntimeError):
    """The ODE library cannot be loaded here (the message says why and how to install it)."""


def library_name() -> str:
    """The ODE library this process loads (METAOPT_ODE_LIBRARY, else libode.so.8)."""
    return os.environ.get(LIBRARY_ENV) or DEFAULT_LIBRARY


class Ode:
    """The loaded library, its functions as attributes (``ode.dWorldStep(world, 0.02)``)."""

    def __init__(self) -> None:
        name = library_name()
        try:
            library = ctypes.CDLL(name)
        except OSError as error:
            raise OdeUnavailable(
                f"cannot load the ODE library ({error}); install it with: {INSTALL_COMMAND}"
            ) from None
        for function, (restype, argtypes) in _SIGNATURES.items():
            bound = getattr(library, function)
            bound.restype, bound.argtypes = restype, argtypes
            setattr(self, function, bound)
        self.dInitODE2(0)
        configuration = self.dGetConfiguration().decode()
        if "ODE_double_precision" not in configuration.split():
            raise OdeUnavailable(
                f"the ODE library {name} is built in single precision; metaopt needs the "
                f"double-precision build ({INSTALL_COMMAND})"
            )


_loaded: Ode | None = None


def library_file() -> str:
    """The name of the file the loaded ODE library is, links resolved (e.g. libode.so.8.0.2,
    Debian's libode8 0.16.2): which build runs, since ODE's C API has no version call."""
    ode()
    with open("/proc/self/maps", encoding="utf-8") as maps:
        for line in maps:
            path = line.split()[-1]
            if "libode" in path.rsplit("/", 1)[-1]:
                return os.path.basename(os.path.realpath(path))
    return library_name()


def ode() -> Ode:
    """The ODE library, loaded and initialised on first use (OdeUnavailable if it cannot be)."""
    global _loaded
    if _loaded is None:
        _loaded = Ode()
    return _loaded
