// gui: the photographer's window, `carousel-studio` (contract; a later issue builds it).
//
// Immediate-mode panels drawing app-owned state: rig status and live view, a capture button,
// a progress bar per pipeline stage, the model preview, errors shown in the window. Long work
// runs on a worker thread through studio's pipeline with a core::Progress; decision logic
// lives in testable code outside ImGui.
#pragma once
