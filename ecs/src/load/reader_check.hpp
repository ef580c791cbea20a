#pragma once
// Reading a file first in a separate process, for the libraries that crash
// or hang on some corrupt files (assimp: a double free in its FBX parser, an
// endless loop on a PLY cut inside its header; OpenVDB: corrupt compressed
// blocks, and trees leaked when a read fails midway). The check process
// (setReaderCheckCommand: rtlab's own `rtlab __check-file KIND PID FILE
// [ARGUMENT]`) reads the file as this process is about to; a crash or a hang
// there is an InputError here, so this process reads only files the check
// read. A fresh process, not a fork: forking the multi-threaded rtlab
// deadlocked the child under ASan. Its limits: checkSecondsLimit, and an
// address space of 1 GiB + 256 bytes per byte of the file (none under ASan).
#include <cstdint>
#include <filesystem>
#include <string>

namespace rtlab::ecs::load {

// Runs the check of `kind` ("assimp", "vdb") on `path`; returns when it read
// the file (or when no check command is set, or the check cannot start: then
// the caller reads in process). Throws InputError(where, ...) with the
// check's own one line when it found the file bad, or saying that `library`
// crashed or hung reading it.
// The check's time limit for a file of `fileBytes`: 1 s per KB, at least 2 s
// and at most 30 s + 2 s per MB (no input takes more than a second per KB to
// reject, yet a big valid file has time to load).
double checkSecondsLimit(std::uint64_t fileBytes);

void checkInSeparateProcess(const std::string& kind, const std::string& library, const std::filesystem::path& path,
                            const std::string& argument, const std::string& where);

// The checks themselves, run in the check process by runReaderCheck: each
// reads the file as its loader does, InputError on bad input.
void readWithAssimpForCheck(const std::filesystem::path& path);
void readVdbForCheck(const std::filesystem::path& path, const std::string& gridName);

}  // namespace rtlab::ecs::load
