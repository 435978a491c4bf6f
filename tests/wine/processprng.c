/* bcryptprimitives.dll for wine 8, which lacks it: Rust's standard library imports
 * ProcessPrng from it for its random numbers (HashMap keys). Windows 10 and later have it;
 * this stand-in gets the same bytes from BCryptGenRandom, which wine has. Built by
 * .ci/windows-wine.sh and put on WINEPATH; never shipped. */
#include <windows.h>
#include <bcrypt.h>

BOOL WINAPI ProcessPrng(PBYTE data, SIZE_T len)
{
    while (len > 0) {
        ULONG chunk = len > 0x40000000 ? 0x40000000 : (ULONG)len;
        if (!BCRYPT_SUCCESS(BCryptGenRandom(NULL, data, chunk, BCRYPT_USE_SYSTEM_PREFERRED_RNG)))
            return FALSE;
        data += chunk;
        len -= chunk;
    }
    return TRUE;
}
