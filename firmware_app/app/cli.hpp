// The edgetrack command line (INTERFACES §3): parses arguments and runs one sub-command.
#pragma once

#include <ostream>

namespace edgetrack::app {

/// \brief Exit code of a sub-command that is recognised but not yet built.
inline constexpr int kExitNotBuilt = 2;
/// \brief Exit code for bad arguments or bad input.
inline constexpr int kExitUsage = 2;
inline constexpr int kExitFailure = 1;

/**
 * \brief Parse \a argv and run the chosen sub-command.
 * \return the process exit code: 0 on success, non-zero after one line of error on \a err.
 */
int runCommandLine(int argc, const char* const* argv, std::ostream& out, std::ostream& err);

} // namespace edgetrack::app
