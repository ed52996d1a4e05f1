// sim: the virtual rig (contract; issues 3, 7 and 8 build it).
//
//   - scene loading (glTF 2.0 through tinygltf, OBJ+MTL) placed on the turntable plate;
//   - a deterministic, multithreaded CPU renderer through a CameraModel (perspective-correct
//     textures, anti-aliased edges, lens distortion, studio backdrop, noise, JPEG) that also
//     writes ground-truth masks and depth;
//   - SimCamera and SimTurntable implementing carousel_rig_api;
//   - the PTP/IP camera emulator that real libgphoto2 talks to;
//   - the simavr harness that runs the real turntable firmware.
#pragma once
