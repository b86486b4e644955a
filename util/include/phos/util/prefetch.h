// Prefetch: asks for the cache line holding p ahead of a read that would
// miss it (a large mesh's tables, read at random per ray).
#pragma once

namespace phos {

// An asm statement, not __builtin_prefetch: GCC 12 at -O3 deleted builtin
// prefetches whose address was computed in inlined code (the path tracer's
// prefetch of an alias-table column compiled to nothing, and a reduced case
// kept or lost it depending on how the same address was spelled). A volatile
// asm is never deleted. It does not fault on any address.
inline void Prefetch(const void* p) {
#if defined(__x86_64__) || defined(__i386__)
  asm volatile("prefetcht0 %0" : : "m"(*static_cast<const char*>(p)));
#else
  __builtin_prefetch(p);
#endif
}

}  // namespace phos
