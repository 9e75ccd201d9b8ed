// toml++'s implementation, compiled once here; every other file includes its declarations only.
#define TOML_IMPLEMENTATION
#include <toml++/toml.h>
