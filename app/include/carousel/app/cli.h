// The `carousel` command-line program: a table of command groups (app/src/main.cpp), one source
// file per group, each parsing its flags into a stage's Options (made from the options'
// descriptions, core/options.h) and calling the studio library. Nothing else lives here.
//
// Exit codes (sysexits-style, stable for scripts):
#pragma once

#include <exception>
#include <iosfwd>

namespace carousel::app {

enum ExitCode : int {
  kExitOk = 0,
  kExitFailure = 1,       // any other carousel::Error, or an internal error
  kExitUsage = 64,        // bad command line or option value (InvalidArgument)
  kExitDataError = 65,    // an input file is malformed (FormatError)
  kExitUnavailable = 69,  // the subcommand is not built yet
  kExitIoError = 74,      // a file or folder could not be read or written (IoError)
  kExitDeviceError = 75,  // a camera, turntable or port failed (DeviceError)
  kExitProtocol = 76,     // a device broke its protocol (ProtocolError)
  kExitCancelled = 130,   // cancelled by the user (Ctrl-C)
};

// The exit code for an error a command let through.
int ExitCodeFor(const std::exception& error);

// Runs the program with `argv` and returns its exit code; writes normal output to `out` and
// errors and progress to `err`. Never throws.
int RunCli(int argc, const char* const* argv, std::ostream& out, std::ostream& err);

}  // namespace carousel::app
