// The main of phos-<command>: app/CMakeLists.txt compiles this file once per
// command with PHOS_COMMAND (its name) and PHOS_REGISTER (its Register function).

#include "commands.h"

int main(int argc, char** argv) { return phos::app::RunCommand(argc, argv, PHOS_COMMAND, &phos::app::PHOS_REGISTER); }
